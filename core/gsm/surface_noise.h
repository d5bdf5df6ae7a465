// How noisy a session's depth really is (ours). Before a frame is fused, a fixed grid of its
// pixels is compared with the map: the TSDF distance at each measured point is how far that
// measurement lies from the surface the earlier frames agreed on (sensor noise, and the error of
// the poses). Each residual is divided by the depth-noise model's σ(z) (ModelParams::depthNoise,
// Kinect-class) at the point's depth; the session's noise scale is the median of those ratios
// over 0.6745 (the median of |x| for a unit Gaussian). About 1: the depth is as noisy as the
// model says; a synthetic world with exact poses is far below 1; a real sweep whose poses
// disagree by centimetres is above. The database loosens its thresholds by this measured scale
// (MergingParams::noise_sigmas), not by the model alone.
#pragma once

#include <array>
#include <cstdint>

#include "core/common/image.h"
#include "core/common/intrinsics.h"
#include "core/common/params.h"
#include "core/common/transform.h"
#include "core/tsdf/tsdf_layer.h"

namespace objdb::gsm {

class SurfaceNoise {
 public:
  // Residuals count only where the map's interpolated weight is at least this (a surface seen
  // by several frames) and the distance is below this share of the truncation (not clamped).
  static constexpr float kMinWeight = 3.0f;
  static constexpr float kMaxTruncationShare = 0.8f;
  // Pixels sampled per frame: a grid of kGridX × kGridY.
  static constexpr int kGridX = 20, kGridY = 15;

  explicit SurfaceNoise(const ModelParams& noise_model = {}) : model_(noise_model) {}

  // Compares `depth` (camera T_world_camera) with `map` before the frame is fused into it. A
  // pose that is not finite adds nothing.
  void sample(const tsdf::TsdfLayer& map, const DepthImage& depth, const Transform& T_world_camera,
              const Intrinsics& intrinsics, float truncation_m);
  // The measured scale (0 while fewer than kMinSamples residuals were seen: unknown).
  float scale() const;
  static constexpr int64_t kMinSamples = 200;
  int64_t samples() const { return samples_; }
  // Adds another's residuals (one frame's, once the frame was fused without error).
  void add(const SurfaceNoise& other);
  const ModelParams& model() const { return model_; }

 private:
  // Ratios |residual| / σ(z) in bins of kBinWidth; the last bin holds everything beyond.
  static constexpr float kBinWidth = 0.02f;
  static constexpr int kBins = 500;
  ModelParams model_;
  std::array<int64_t, kBins> histogram_{};
  int64_t samples_ = 0;
};

}  // namespace objdb::gsm
