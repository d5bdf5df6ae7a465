// PCL-backed geometry of object models: planarity (RANSAC plane), keypoints (ISS ∪ Harris3D) and
// FPFH descriptors. PCL stays inside features.cpp: nothing here includes it.
#pragma once

#include <cstdint>
#include <vector>

#include "core/common/mesh.h"
#include "core/common/params.h"
#include "core/model/object_model.h"

namespace objdb::model {

struct PlaneFit {
  Eigen::Vector4f coefficients = Eigen::Vector4f::Zero();  // n·p + d = 0, |n| = 1
  float inlier_ratio = 0.0f;
};
// Best plane by RANSAC (deterministic seed). Fewer than 3 points: inlier_ratio 0.
PlaneFit fitPlane(const PointCloud& cloud, float distance_m, int iterations);

// One plane of a cloud and the points within distance of it.
struct PlanePiece {
  Eigen::Vector4f coefficients = Eigen::Vector4f::Zero();  // n·p + d = 0, |n| = 1
  std::vector<uint32_t> inliers;                           // indices into the cloud, ascending
};
// Up to `max_planes` planes, each the best RANSAC plane (deterministic seed) of the points the
// planes before it left, with its inliers refined on the fitted plane; stops at a plane with
// fewer than `min_inliers` points (not returned).
std::vector<PlanePiece> fitPlanes(const PointCloud& cloud, float distance_m, int iterations,
                                  int max_planes, size_t min_inliers);

struct KeypointCounts {
  size_t iss = 0, harris = 0, both = 0;
  size_t uniform = 0;  // added by uniform_spacing_m (not already ISS or Harris3D)
};
// ISS (r_s, r_nm, r_b, k_min of table I) ∪ Harris3D (r_H, t_resp; then k_min neighbours within
// r_H and surface variation λ0/(λ0+λ1+λ2) ≥ t_curv, which PCL's detector does not apply) as
// indices into the cloud, ascending. The cloud needs normals. `threads` > 1 runs ISS and Harris3D
// on that many OpenMP threads; the result does not depend on it.
std::vector<uint32_t> detectKeypoints(const PointCloud& cloud, const KeypointParams& params,
                                      KeypointCounts* counts = nullptr, int threads = 1);

// FPFH (radius r) at the given cloud points, over the whole cloud as search surface. Keypoints
// whose descriptor is undefined (too few neighbours) are dropped from `indices`. `threads` > 1
// computes them on that many OpenMP threads (PCL's FPFHEstimationOMP); the same result.
std::vector<Fpfh> computeFpfh(const PointCloud& cloud, std::vector<uint32_t>* indices,
                              const DescriptorParams& params, int threads = 1);

}  // namespace objdb::model
