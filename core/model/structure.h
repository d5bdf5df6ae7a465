// Room structure and planarity of a segment's surface (paper §III-C.1's planarity test, made
// noise-aware; room structure is ours, issue 17). The distance a point may lie off a plane
// follows the sensor's axial noise at the depth the segment was seen from
// (ModelParams::planeDistance). A segment is planar when one plane holds most of its points;
// it is structure when a plane bigger than an object can be (both in-plane spans at least
// structure_min_extent_m) holds a good share of them: floors, walls, ceilings, partitions, with
// whatever sticks to them. Both are stored and never matched; structure is listed as such.
#pragma once

#include <string>

#include "core/common/mesh.h"
#include "core/common/params.h"

namespace objdb::model {

struct SurfaceClass {
  bool planar = false;
  bool structure = false;
  float plane_distance_m = 0.0f;   // the inlier distance used
  float plane_inlier_ratio = 0.0f; // share of points on the best plane
  // The plane that made it structure (or the largest plane found): its share of the points and
  // its in-plane spans (5th to 95th percentile of its inliers along its two principal axes).
  float structure_share = 0.0f;
  float structure_span_m[2] = {0.0f, 0.0f};
  int planes = 0;                  // planes found (at most structure_max_planes)
};

// Classifies a surface cloud seen from `depth_m` (0 = unknown: the plane_distance_m floor).
SurfaceClass classifySurface(const PointCloud& cloud, float depth_m, const ModelParams& params);

}  // namespace objdb::model
