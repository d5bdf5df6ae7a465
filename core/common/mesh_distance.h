// Exact point-to-surface distances against a triangle mesh, and even surface sampling: the
// ground-truth side of the surface-accuracy and completion metrics (GSM issue: mean distance of
// reconstructed vertices to the true surfaces; database issue: share of a true surface within
// 2 cm of a reconstruction).
#pragma once

#include <cstdint>
#include <limits>
#include <vector>

#include <Eigen/Core>

#include "absl/container/flat_hash_map.h"
#include "core/common/mesh.h"
#include "core/common/status.h"

namespace objdb {

// Distance from p to the triangle (a, b, c), exact (closest point on the triangle, degenerate
// triangles handled as segments / points).
float pointTriangleDistance(const Eigen::Vector3f& p, const Eigen::Vector3f& a,
                            const Eigen::Vector3f& b, const Eigen::Vector3f& c);

// Triangles bucketed in a uniform grid of cell = max_distance: a query looks at the 27 cells
// around the point and returns the exact distance to the nearest triangle, or +inf when none is
// within max_distance. Triangles are bucketed into every cell their bounding box touches.
class MeshDistance {
 public:
  // Errors: max_distance not positive or not finite; a triangle index out of range; more than
  // `max_cells` grid cells would be needed (a huge mesh with a tiny max_distance).
  static StatusOr<MeshDistance> create(const TriangleMesh& mesh, float max_distance,
                                       size_t max_cells = size_t(1) << 26);

  float maxDistance() const { return max_distance_; }
  // Nearest-triangle distance, +inf beyond maxDistance().
  float distance(const Eigen::Vector3f& p) const;

 private:
  MeshDistance() = default;
  Eigen::Vector3i cellOf(const Eigen::Vector3f& p) const;

  float max_distance_ = 0.0f;
  std::vector<Eigen::Vector3f> vertices_;
  std::vector<Eigen::Vector3i> triangles_;
  absl::flat_hash_map<uint64_t, std::vector<uint32_t>> cells_;
};

// Points spread over the mesh surface about `spacing` apart: each triangle gets
// round(area / spacing²) points (at least its centroid when `every_triangle`) on a deterministic
// low-discrepancy pattern. Errors: spacing not positive.
StatusOr<std::vector<Eigen::Vector3f>> sampleSurface(const TriangleMesh& mesh, float spacing,
                                                     bool every_triangle = false);

// Summary of a set of distances (+inf entries count as `beyond`, not in the statistics).
struct DistanceStats {
  size_t count = 0;    // finite distances
  size_t beyond = 0;   // +inf (nothing within the search distance)
  double mean = 0.0, median = 0.0, p90 = 0.0, max = 0.0;
  // Share of all distances (incl. beyond) at or below `threshold`.
  double shareWithin(double threshold) const;
  std::vector<float> sorted;  // the finite distances, ascending
};
DistanceStats summarizeDistances(std::vector<float> distances);

}  // namespace objdb
