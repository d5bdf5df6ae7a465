#include "core/common/mesh_distance.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Geometry>

#include "absl/strings/str_format.h"
#include "core/common/grid_key.h"

namespace objdb {
namespace {

float pointSegmentDistance(const Eigen::Vector3f& p, const Eigen::Vector3f& a,
                           const Eigen::Vector3f& b) {
  const Eigen::Vector3f ab = b - a;
  const float len2 = ab.squaredNorm();
  const float t = len2 > 0.0f ? std::clamp((p - a).dot(ab) / len2, 0.0f, 1.0f) : 0.0f;
  return (a + t * ab - p).norm();
}

}  // namespace

float pointTriangleDistance(const Eigen::Vector3f& p, const Eigen::Vector3f& a,
                            const Eigen::Vector3f& b, const Eigen::Vector3f& c) {
  const Eigen::Vector3f ab = b - a, ac = c - a;
  const Eigen::Vector3f n = ab.cross(ac);
  const float n2 = n.squaredNorm();
  if (!(n2 > 1e-12f * ab.squaredNorm() * ac.squaredNorm())) {
    // Degenerate: the nearest of its three edges.
    return std::min({pointSegmentDistance(p, a, b), pointSegmentDistance(p, b, c),
                     pointSegmentDistance(p, c, a)});
  }
  // Barycentric coordinates of p's projection onto the plane.
  const Eigen::Vector3f ap = p - a;
  const float v = ap.cross(ac).dot(n) / n2;   // weight of b
  const float w = ab.cross(ap).dot(n) / n2;   // weight of c
  if (v >= 0.0f && w >= 0.0f && v + w <= 1.0f) return std::abs(ap.dot(n)) / std::sqrt(n2);
  // Outside: the nearest point lies on an edge.
  return std::min({pointSegmentDistance(p, a, b), pointSegmentDistance(p, b, c),
                   pointSegmentDistance(p, c, a)});
}

Eigen::Vector3i MeshDistance::cellOf(const Eigen::Vector3f& p) const {
  return (p / max_distance_).array().floor().cast<int>();
}

StatusOr<MeshDistance> MeshDistance::create(const TriangleMesh& mesh, float max_distance,
                                            size_t max_cells) {
  if (!(max_distance > 0.0f) || !std::isfinite(max_distance)) {
    return absl::InvalidArgumentError(
        absl::StrFormat("mesh distance: max_distance must be positive and finite, got %g",
                        max_distance));
  }
  OBJDB_RETURN_IF_ERROR(mesh.validate());
  MeshDistance index;
  index.max_distance_ = max_distance;
  index.vertices_ = mesh.vertices;
  index.triangles_ = mesh.triangles;
  size_t cells = 0;
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    const Eigen::Vector3i& tri = mesh.triangles[t];
    Eigen::Vector3f lo = mesh.vertices[size_t(tri[0])], hi = lo;
    for (int k = 1; k < 3; ++k) {
      lo = lo.cwiseMin(mesh.vertices[size_t(tri[k])]);
      hi = hi.cwiseMax(mesh.vertices[size_t(tri[k])]);
    }
    const Eigen::Vector3i c0 = index.cellOf(lo), c1 = index.cellOf(hi);
    const Eigen::Vector3i span = c1 - c0 + Eigen::Vector3i::Ones();
    cells += size_t(span.x()) * size_t(span.y()) * size_t(span.z());
    if (cells > max_cells) {
      return absl::ResourceExhaustedError(absl::StrFormat(
          "mesh distance: more than %d grid cells at max_distance %g m; use a larger distance",
          max_cells, max_distance));
    }
    for (int z = c0.z(); z <= c1.z(); ++z) {
      for (int y = c0.y(); y <= c1.y(); ++y) {
        for (int x = c0.x(); x <= c1.x(); ++x) {
          index.cells_[packGridKey({x, y, z})].push_back(uint32_t(t));
        }
      }
    }
  }
  return index;
}

float MeshDistance::distance(const Eigen::Vector3f& p) const {
  float best = std::numeric_limits<float>::infinity();
  if (!p.allFinite()) return best;
  const Eigen::Vector3i c = cellOf(p);
  // A triangle within max_distance of p touches one of the 27 cells around p's cell (it has a
  // point within max_distance, and that point's cell is a neighbour); a triangle listed in two
  // of those cells is measured twice, which is cheaper than de-duplicating.
  for (int dz = -1; dz <= 1; ++dz) {
    for (int dy = -1; dy <= 1; ++dy) {
      for (int dx = -1; dx <= 1; ++dx) {
        const auto it = cells_.find(packGridKey(c + Eigen::Vector3i(dx, dy, dz)));
        if (it == cells_.end()) continue;
        for (uint32_t t : it->second) {
          const Eigen::Vector3i& tri = triangles_[t];
          best = std::min(best, pointTriangleDistance(p, vertices_[size_t(tri[0])],
                                                      vertices_[size_t(tri[1])],
                                                      vertices_[size_t(tri[2])]));
        }
      }
    }
  }
  return best <= max_distance_ ? best : std::numeric_limits<float>::infinity();
}

StatusOr<std::vector<Eigen::Vector3f>> sampleSurface(const TriangleMesh& mesh, float spacing,
                                                     bool every_triangle) {
  if (!(spacing > 0.0f) || !std::isfinite(spacing)) {
    return absl::InvalidArgumentError(
        absl::StrFormat("surface sampling: spacing must be positive and finite, got %g", spacing));
  }
  OBJDB_RETURN_IF_ERROR(mesh.validate());
  std::vector<Eigen::Vector3f> points;
  // Carry the fractional share over so small triangles (a tessellated sphere) still add up.
  double carry = 0.0;
  for (const Eigen::Vector3i& tri : mesh.triangles) {
    const Eigen::Vector3f& a = mesh.vertices[size_t(tri[0])];
    const Eigen::Vector3f& b = mesh.vertices[size_t(tri[1])];
    const Eigen::Vector3f& c = mesh.vertices[size_t(tri[2])];
    const double area = 0.5 * double((b - a).cross(c - a).norm());
    const double want = area / (double(spacing) * double(spacing)) + carry;
    size_t n = size_t(std::floor(want));
    carry = want - double(n);
    if (n == 0 && every_triangle) n = 1;
    // R2 sequence (Roberts 2018) folded into the triangle: even, deterministic.
    constexpr double g1 = 0.7548776662466927, g2 = 0.5698402909980532;
    for (size_t i = 0; i < n; ++i) {
      double r1 = std::fmod(0.5 + g1 * double(i + 1), 1.0);
      double r2 = std::fmod(0.5 + g2 * double(i + 1), 1.0);
      if (r1 + r2 > 1.0) {
        r1 = 1.0 - r1;
        r2 = 1.0 - r2;
      }
      points.push_back(a + float(r1) * (b - a) + float(r2) * (c - a));
    }
  }
  return points;
}

double DistanceStats::shareWithin(double threshold) const {
  const size_t total = count + beyond;
  if (total == 0) return 0.0;
  const size_t within =
      size_t(std::upper_bound(sorted.begin(), sorted.end(), float(threshold)) - sorted.begin());
  return double(within) / double(total);
}

DistanceStats summarizeDistances(std::vector<float> distances) {
  DistanceStats stats;
  for (float d : distances) {
    if (std::isfinite(d)) {
      stats.sorted.push_back(d);
    } else {
      ++stats.beyond;
    }
  }
  std::sort(stats.sorted.begin(), stats.sorted.end());
  stats.count = stats.sorted.size();
  if (stats.count == 0) return stats;
  double sum = 0.0;
  for (float d : stats.sorted) sum += d;
  stats.mean = sum / double(stats.count);
  stats.median = stats.sorted[stats.count / 2];
  stats.p90 = stats.sorted[std::min(stats.count - 1, size_t(0.9 * double(stats.count)))];
  stats.max = stats.sorted.back();
  return stats;
}

}  // namespace objdb
