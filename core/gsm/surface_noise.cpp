#include "core/gsm/surface_noise.h"

#include <algorithm>
#include <cmath>

namespace objdb::gsm {

void SurfaceNoise::sample(const tsdf::TsdfLayer& map, const DepthImage& depth,
                          const Transform& T_world_camera, const Intrinsics& intrinsics,
                          float truncation_m) {
  if (depth.width <= 0 || depth.height <= 0 || !T_world_camera.matrix().allFinite()) return;
  const Eigen::Isometry3f T = T_world_camera.cast<float>();
  const float limit = kMaxTruncationShare * truncation_m;
  for (int gy = 0; gy < kGridY; ++gy) {
    const int v = int((gy + 0.5) * depth.height / kGridY);
    for (int gx = 0; gx < kGridX; ++gx) {
      const int u = int((gx + 0.5) * depth.width / kGridX);
      const float z = depth.at(u, v);
      if (!isValidDepth(z)) continue;
      const float sigma = model_.depthNoise(z);
      if (!(sigma > 0.0f)) continue;
      const Eigen::Vector3f p = T * intrinsics.backProject(u, v, z).cast<float>();
      float distance = 0.0f, weight = 0.0f;
      if (!map.interpolate(p, &distance, &weight) || weight < kMinWeight) continue;
      if (!(std::abs(distance) < limit)) continue;
      const int bin = std::min(kBins - 1, int(std::abs(distance) / sigma / kBinWidth));
      ++histogram_[size_t(bin)];
      ++samples_;
    }
  }
}

void SurfaceNoise::add(const SurfaceNoise& other) {
  for (int b = 0; b < kBins; ++b) histogram_[size_t(b)] += other.histogram_[size_t(b)];
  samples_ += other.samples_;
}

float SurfaceNoise::scale() const {
  if (samples_ < kMinSamples) return 0.0f;
  const int64_t half = (samples_ + 1) / 2;
  int64_t seen = 0;
  for (int b = 0; b < kBins; ++b) {
    seen += histogram_[size_t(b)];
    if (seen >= half) return (float(b) + 0.5f) * kBinWidth / 0.6745f;
  }
  return float(kBins) * kBinWidth / 0.6745f;
}

}  // namespace objdb::gsm
