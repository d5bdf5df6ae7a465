// Projective TSDF integration of posed depth frames (paper §III-B; the GSM's geometry layer).
// One pass per frame: the blocks within the truncation band of the measured points are collected
// (points bundled per block, so a block is visited once however many points fall into it), then
// every voxel of those blocks is projected into the depth image and updated once — the one-update-
// per-voxel-per-frame property of voxblox's "merged" integrator without ray casting.
//
// Signed distance = measured depth − voxel depth along the optical axis (KinectFusion style:
// exact for surfaces facing the camera, a cos-factor overestimate for slanted ones, zero crossing
// exact either way), truncated at ±truncation. Behind the surface the weight drops linearly to 0
// at −truncation (voxblox's weight drop-off); weights saturate at max_weight.
#pragma once

#include <memory>

#include "core/common/image.h"
#include "core/common/intrinsics.h"
#include "core/common/params.h"
#include "core/common/worker_pool.h"
#include "core/common/transform.h"
#include "core/tsdf/tsdf_layer.h"

namespace objdb::tsdf {

struct IntegrationStats {
  size_t points_used = 0;     // valid depths within [min_ray_length_m, max_ray_length_m]
  size_t invalid_depth = 0;   // 0, NaN, ±inf, negative
  size_t out_of_range = 0;    // valid but outside the ray-length limits
  size_t blocks_touched = 0;
  size_t voxels_updated = 0;
  double milliseconds = 0.0;
};

class TsdfIntegrator {
 public:
  // threads ≥ 1: blocks are split between threads (voxels of different blocks are independent).
  static StatusOr<TsdfIntegrator> create(const TsdfParams& params, const Intrinsics& intrinsics,
                                         int threads = 1);

  // Fuses one frame. Errors (nothing is changed): depth/colour size differs from the intrinsics,
  // pose not finite / not a rotation, layer voxel size differs from the params.
  StatusOr<IntegrationStats> integrate(const DepthImage& depth, const Transform& T_world_camera,
                                       TsdfLayer* layer, const ColorImage* color = nullptr) const;

 private:
  TsdfIntegrator(const TsdfParams& params, const Intrinsics& intrinsics, int threads);
  TsdfParams params_;
  Intrinsics intrinsics_;
  int threads_;
  // The threads − 1 workers, started once (copies of the integrator share them; integrations
  // through copies on different threads take turns on them). Null for one thread.
  std::shared_ptr<WorkerPool> pool_;
};

}  // namespace objdb::tsdf
