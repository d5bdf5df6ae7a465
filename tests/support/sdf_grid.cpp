#include "tests/support/sdf_grid.h"

#include <cmath>

namespace objdb::testing {

SdfGrid sdfGrid(const Sdf& sdf, const Eigen::Vector3f& lo, const Eigen::Vector3f& hi, float voxel,
                float band, float weight, int voxels_per_side) {
  SdfGrid grid{tsdf::TsdfLayer::create(voxel, voxels_per_side).value(), {}};
  tsdf::TsdfLayer& layer = grid.layer;
  const tsdf::VoxelIndex a = layer.voxelIndexOf(lo), b = layer.voxelIndexOf(hi);
  for (int z = a.z(); z <= b.z(); ++z) {
    for (int y = a.y(); y <= b.y(); ++y) {
      for (int x = a.x(); x <= b.x(); ++x) {
        const tsdf::VoxelIndex v(x, y, z);
        const float d = sdf(layer.voxelCenter(v));
        if (!(std::abs(d) <= band)) continue;
        layer.allocateBlock(layer.blockOfVoxel(v));
        tsdf::TsdfVoxel* out = layer.voxel(v);
        out->distance = d;
        out->weight = weight;
        if (std::abs(d) <= voxel) grid.surface_voxels.push_back(v);
      }
    }
  }
  return grid;
}

Sdf sphereSdf(const Eigen::Vector3f& centre, float radius) {
  return [=](const Eigen::Vector3f& p) { return (p - centre).norm() - radius; };
}

Sdf boxSdf(const Eigen::Vector3f& centre, const Eigen::Vector3f& half) {
  return [=](const Eigen::Vector3f& p) {
    const Eigen::Vector3f q = (p - centre).cwiseAbs() - half;
    return q.cwiseMax(0.0f).norm() + std::min(q.maxCoeff(), 0.0f);
  };
}

Sdf cylinderSdf(const Eigen::Vector3f& centre, float radius, float half_height) {
  return [=](const Eigen::Vector3f& p) {
    const Eigen::Vector3f q = p - centre;
    const Eigen::Vector2f d(q.head<2>().norm() - radius, std::abs(q.z()) - half_height);
    return std::min(std::max(d.x(), d.y()), 0.0f) + d.cwiseMax(0.0f).norm();
  };
}

Sdf unionSdf(std::vector<Sdf> parts) {
  return [parts = std::move(parts)](const Eigen::Vector3f& p) {
    float d = INFINITY;
    for (const auto& s : parts) d = std::min(d, s(p));
    return d;
  };
}

Sdf transformedSdf(const Sdf& sdf, const Eigen::Isometry3f& T) {
  const Eigen::Isometry3f inv = T.inverse();
  return [=](const Eigen::Vector3f& p) { return sdf(inv * p); };
}

}  // namespace objdb::testing
