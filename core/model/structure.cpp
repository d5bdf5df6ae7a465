#include "core/model/structure.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include <Eigen/Eigenvalues>

#include "core/model/features.h"

namespace objdb::model {
namespace {

// 5th to 95th percentile spans of `inliers` along the two principal axes of their spread within
// the plane with normal `n` (robust to a few stray points).
void planeSpans(const PointCloud& cloud, const std::vector<uint32_t>& inliers,
                const Eigen::Vector3f& n, float spans[2]) {
  spans[0] = spans[1] = 0.0f;
  if (inliers.size() < 3) return;
  // In-plane basis, then the principal axes of the projected points.
  const Eigen::Vector3f a =
      (std::abs(n.x()) < 0.9f ? Eigen::Vector3f::UnitX() : Eigen::Vector3f::UnitY()).cross(n).normalized();
  const Eigen::Vector3f b = n.cross(a);
  std::vector<Eigen::Vector2f> uv;
  uv.reserve(inliers.size());
  Eigen::Vector2f mean = Eigen::Vector2f::Zero();
  for (uint32_t i : inliers) {
    const Eigen::Vector3f& p = cloud.points[i];
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
  out.planar = out.plane_inlier_ratio >= params.planar_inlier_ratio;
  if (params.structure_max_planes <= 0) return out;
  for (const PlanePiece& plane : planes) {
    const float share = float(plane.inliers.size()) / float(n);
    float spans[2];
    planeSpans(cloud, plane.inliers, plane.coefficients.head<3>(), spans);
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

}  // namespace objdb::model
