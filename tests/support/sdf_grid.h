// TSDF grids of analytic shapes with known distances, for tests of everything that reads grids.
#pragma once

#include <functional>
#include <vector>

#include <Eigen/Geometry>

#include "core/tsdf/tsdf_layer.h"

namespace objdb::testing {

using Sdf = std::function<float(const Eigen::Vector3f&)>;

struct SdfGrid {
  tsdf::TsdfLayer layer;
  std::vector<tsdf::VoxelIndex> surface_voxels;  // |distance| ≤ one voxel: "the label's voxels"
};

// Every voxel of [lo, hi] within `band` of the surface gets its exact signed distance (positive
// outside) and `weight`.
SdfGrid sdfGrid(const Sdf& sdf, const Eigen::Vector3f& lo, const Eigen::Vector3f& hi, float voxel,
                float band, float weight = 10.0f, int voxels_per_side = 8);

Sdf sphereSdf(const Eigen::Vector3f& centre, float radius);
// Axis-aligned box with the given centre and half extents (exact distance inside and out).
Sdf boxSdf(const Eigen::Vector3f& centre, const Eigen::Vector3f& half);
// Capped cylinder along z: radius, half height.
Sdf cylinderSdf(const Eigen::Vector3f& centre, float radius, float half_height);
// Union of shapes (min of distances: exact outside, a lower bound inside).
Sdf unionSdf(std::vector<Sdf> parts);
// The shape moved by T (p ↦ sdf(T⁻¹ p)).
Sdf transformedSdf(const Sdf& sdf, const Eigen::Isometry3f& T);

}  // namespace objdb::testing
