// Room structure and planarity of a segment's surface (paper §III-C.1's planarity test, made
// noise-aware; room structure is ours). The distance a point may lie off a plane
// follows the sensor's axial noise at the depth the segment was seen from
// (ModelParams::planeDistance). A segment is planar when one plane holds most of its points;
// it is structure when a plane bigger than an object can be (both in-plane spans at least
// structure_min_extent_m) holds a good share of them: floors, walls, ceilings, partitions, with
// whatever sticks to them. Both are stored and never matched; structure is listed as such.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/common/mesh.h"
#include "core/common/params.h"
#include "core/tsdf/tsdf_layer.h"

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
  // The best plane (n·p + d = 0, |n| = 1, the cloud's frame), for growing it through the scene.
  Eigen::Vector4f plane = Eigen::Vector4f::Zero();
  // Every plane found holding at least structure_min_share of the points, best first: each is
  // grown through the scene (a floor plus a strip of wall: both pieces, either may be the big one).
  std::vector<Eigen::Vector4f> shared_planes;
};

// Classifies a surface cloud seen from `depth_m` (0 = unknown: the plane_distance_m floor).
SurfaceClass classifySurface(const PointCloud& cloud, float depth_m, const ModelParams& params);

// The segment's best plane grown through the scene: from the scene's surface voxels under
// `seeds` (world points on the plane), every 26-connected surface voxel (|distance| ≤ half a
// voxel, observed) within `distance_m` + half a voxel of the plane, up to `max_voxels`. Returns
// its in-plane spans (5th to 95th percentile along its principal axes, smaller first). A piece of
// a partition or a wall that segmentation cut out grows to the whole face; a chair's seat stops
// at its own edges.
struct GrownPlane {
  size_t voxels = 0;
  float span_m[2] = {0.0f, 0.0f};
};
GrownPlane growPlaneInScene(const tsdf::TsdfLayer& scene, const Eigen::Vector4f& plane_world,
                            const std::vector<Eigen::Vector3f>& seeds, float distance_m,
                            size_t max_voxels = 400000);

}  // namespace objdb::model
