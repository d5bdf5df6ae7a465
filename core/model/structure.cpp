#include "core/model/structure.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include <Eigen/Eigenvalues>

#include "absl/container/flat_hash_set.h"
#include "core/common/grid_key.h"
#include "core/common/plane_spans.h"
#include "core/model/features.h"

namespace objdb::model {

SurfaceClass classifySurface(const PointCloud& cloud, float depth_m, const ModelParams& params) {
  SurfaceClass out;
  out.plane_distance_m = params.planeDistance(depth_m);
  if (cloud.points.size() < 3) return out;
  const size_t n = cloud.points.size();
  const int max_planes = std::max(1, params.structure_max_planes);
  // Planes holding less than structure_min_share cannot decide anything: stop at them.
  const size_t min_inliers =
      std::max<size_t>(3, size_t(std::ceil(params.structure_min_share * float(n))));
  const std::vector<PlanePiece> planes =
      fitPlanes(cloud, out.plane_distance_m, params.plane_ransac_iterations, max_planes,
                std::min(min_inliers, n));
  out.planes = int(planes.size());
  if (planes.empty()) return out;
  out.plane_inlier_ratio = float(planes.front().inliers.size()) / float(n);
  out.plane = planes.front().coefficients;
  out.planar = out.plane_inlier_ratio >= params.planar_inlier_ratio;
  if (params.structure_max_planes <= 0) return out;
  for (const PlanePiece& plane : planes) {
    const float share = float(plane.inliers.size()) / float(n);
    if (share >= params.structure_min_share) out.shared_planes.push_back(plane.coefficients);
    float spans[2];
    planeSpans(
        plane.inliers.size(), [&](size_t i) { return cloud.points[plane.inliers[i]]; },
        plane.coefficients.head<3>(), spans);
    const bool big = spans[0] >= params.structure_min_extent_m;
    // Report the deciding plane, else the one with the largest smaller span.
    if (big || spans[0] > out.structure_span_m[0]) {
      out.structure_share = share;
      out.structure_span_m[0] = spans[0];
      out.structure_span_m[1] = spans[1];
    }
    if (big && share >= params.structure_min_share) {
      out.structure = true;
      break;
    }
  }
  return out;
}

GrownPlane growPlaneInScene(const tsdf::TsdfLayer& scene, const Eigen::Vector4f& plane_world,
                            const std::vector<Eigen::Vector3f>& seeds, float distance_m,
                            size_t max_voxels) {
  GrownPlane out;
  const Eigen::Vector3f n = plane_world.head<3>();
  const float voxel = scene.voxelSize();
  const float near_plane = distance_m + 0.5f * voxel;
  auto onPlane = [&](const tsdf::VoxelIndex& v) {
    const tsdf::TsdfVoxel* x = scene.voxel(v);
    if (x == nullptr || !(x->weight > 0.0f) || !(std::abs(x->distance) <= 0.5f * voxel)) {
      return false;
    }
    return std::abs(n.dot(scene.voxelCenter(v)) + plane_world.w()) <= near_plane;
  };
  absl::flat_hash_set<uint64_t> seen;
  std::vector<tsdf::VoxelIndex> frontier, region;
  for (const auto& p : seeds) {
    const tsdf::VoxelIndex v = scene.voxelIndexOf(p);
    if (onPlane(v) && seen.insert(packGridKey(v)).second) frontier.push_back(v);
  }
  while (!frontier.empty() && region.size() < max_voxels) {
    const tsdf::VoxelIndex v = frontier.back();
    frontier.pop_back();
    region.push_back(v);
    for (int dz = -1; dz <= 1; ++dz) {
      for (int dy = -1; dy <= 1; ++dy) {
        for (int dx = -1; dx <= 1; ++dx) {
          const tsdf::VoxelIndex w = v + Eigen::Vector3i(dx, dy, dz);
          if (seen.count(packGridKey(w)) != 0 || !onPlane(w)) continue;
          seen.insert(packGridKey(w));
          frontier.push_back(w);
        }
      }
    }
  }
  out.voxels = region.size();
  planeSpans(
      region.size(), [&](size_t i) { return scene.voxelCenter(region[i]); }, n, out.span_m);
  return out;
}

}  // namespace objdb::model
