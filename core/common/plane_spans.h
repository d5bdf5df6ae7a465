// Spans of point sets. planeSpans: the in-plane spans of points on a plane, the 5th to 95th
// percentile of their spread along the two principal axes of their projection (robust to a few
// stray points), shared by the model's structure test (core/model/structure.h) and the map's room
// structure (core/gsm/room_structure.h). principalSpans: the full spans of a cloud along its
// principal axes, what "larger than furniture can be" is measured with (GsmParams::
// object_max_extent_m) by the database and the census of `objdb eval`.
#pragma once

#include <algorithm>
#include <cmath>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Eigenvalues>

namespace objdb {

// Two unit axes spanning the plane with unit normal `n` (a, b, n right-handed).
inline void inPlaneBasis(const Eigen::Vector3f& n, Eigen::Vector3f* a, Eigen::Vector3f* b) {
  *a = (std::abs(n.x()) < 0.9f ? Eigen::Vector3f::UnitX() : Eigen::Vector3f::UnitY())
           .cross(n)
           .normalized();
  *b = n.cross(*a);
}

// `point_at(i)` (i < count) gives the i-th point; `n` is the plane's unit normal. Writes the
// spans, smaller first (0 for fewer than 3 points).
template <typename PointAt>
void planeSpans(size_t count, PointAt point_at, const Eigen::Vector3f& n, float spans[2]) {
  spans[0] = spans[1] = 0.0f;
  if (count < 3) return;
  // In-plane basis, then the principal axes of the projected points.
  Eigen::Vector3f a, b;
  inPlaneBasis(n, &a, &b);
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

// Full spans of `points` along their principal axes, largest first (0 for fewer than 2 points).
inline Eigen::Vector3f principalSpans(const std::vector<Eigen::Vector3f>& points) {
  if (points.size() < 2) return Eigen::Vector3f::Zero();
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& p : points) mean += p.cast<double>();
  mean /= double(points.size());
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (const auto& p : points) {
    const Eigen::Vector3d d = p.cast<double>() - mean;
    cov += d * d.transpose();
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
  Eigen::Vector3f spans;
  for (int a = 0; a < 3; ++a) {
    const Eigen::Vector3f axis = eig.eigenvectors().col(a).cast<float>();
    float lo = 1e30f, hi = -1e30f;
    for (const auto& p : points) {
      lo = std::min(lo, p.dot(axis));
      hi = std::max(hi, p.dot(axis));
    }
    spans(a) = hi - lo;
  }
  std::sort(spans.data(), spans.data() + 3, [](float x, float y) { return x > y; });
  return spans;
}

}  // namespace objdb
