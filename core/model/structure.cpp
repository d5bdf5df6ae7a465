#include "core/model/structure.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include <Eigen/Eigenvalues>

#include "absl/container/flat_hash_set.h"
#include "core/common/grid_key.h"
#include "core/model/features.h"

namespace objdb::model {
namespace {

// 5th to 95th percentile spans of `inliers` along the two principal axes of their spread within
// the plane with normal `n` (robust to a few stray points).
template <typename PointAt>
void planeSpans(size_t count, PointAt point_at, const Eigen::Vector3f& n, float spans[2]) {
  spans[0] = spans[1] = 0.0f;
  if (count < 3) return;
  // In-plane basis, then the principal axes of the projected points.
  const Eigen::Vector3f a =
      (std::abs(n.x()) < 0.9f ? Eigen::Vector3f::UnitX() : Eigen::Vector3f::UnitY()).cross(n).normalized();
  const Eigen::Vector3f b = n.cross(a);
  std::vector<Eigen::Vector2f> uv;
  uv.reserve(count);
  Eigen::Vector2f mean = Eigen::Vector2f::Zero();
  for (size_t i = 0; i < count; ++i) {
    const Eigen::Vector3f p = point_at(i);
    uv.emplace_back(p.dot(a), p.dot(b));
    mean += uv.back();
  }
  mean /= float(uv.size());
  Eigen::Matrix2f cov = Eigen::Matrix2f::Zero();
  for (const auto& q : uv) cov += (q - mean) * (q - mean).transpose();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2f> solver(cov);
  for (int axis = 0; axis < 2; ++axis) {
    const Eigen::Vector2f e = solver.eigenvectors().col(axis);
    std::vector<float> t;
    t.reserve(uv.size());
    for (const auto& q : uv) t.push_back(q.dot(e));
    std::sort(t.begin(), t.end());
    const size_t lo = size_t(0.05 * double(t.size() - 1));
    const size_t hi = size_t(std::ceil(0.95 * double(t.size() - 1)));
    spans[axis] = t[hi] - t[lo];
  }
  if (spans[0] > spans[1]) std::swap(spans[0], spans[1]);  // smaller first
}

}  // namespace

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
