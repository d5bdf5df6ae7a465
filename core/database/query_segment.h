// A query's segment ("what is this?", ObjectDatabase::match): a depth image with a mask, or a
// point cloud, made into the raw segment the GSM would extract for it, so that the segment's
// model is built, retrieved and verified exactly as an inserted one is.
//
// - Depth: the mask's pixels are fused into a fresh TSDF grid at T_world_camera by the frame
//   integrator (tsdf/tsdf_integrator.h, the GSM's own), and the segment's voxels are those its
//   points fall into, as the GSM's label votes make them.
// - Cloud seen from a viewpoint (a depth camera's cloud: `viewpoint`, or its frame's origin when
//   it has no normals): rendered into a virtual depth image from there (each point a disc one
//   voxel across, in its tangent plane when it has a normal; nearest wins), then fused the same
//   way.
// - Cloud with normals and no viewpoint (an object's whole surface, as GetObject returns it): its
//   TSDF straight from the oriented points, each voxel near the surface the signed distance to
//   its nearest point's tangent plane.
//
// One frame gives its voxels weight 1; a map trusts a surface at tsdf.mesh_min_weight (3), which
// a query, having nothing else, cannot reach: its weights are raised to that weight.
#pragma once

#include <cstdint>
#include <optional>
#include <vector>

#include <Eigen/Core>

#include "core/common/image.h"
#include "core/common/intrinsics.h"
#include "core/common/params.h"
#include "core/common/status.h"
#include "core/common/transform.h"
#include "core/gsm/gsm.h"

namespace objdb::database {

// Larger queries are refused (INVALID_ARGUMENT): a chair at 1 cm has ~20,000 surface points,
// a room scan ~2,000,000; a query is one object.
inline constexpr size_t kMaxQueryPoints = 2000000;

struct QueryDepth {
  Intrinsics intrinsics;
  DepthImage depth;                    // metres, intrinsics' size
  const ColorImage* color = nullptr;   // registered to depth, or null
  Transform T_world_camera = Transform::Identity();
  // Row-major, width·height values, non-zero = the segment's pixels; empty: every pixel.
  std::vector<uint8_t> mask;
};

struct QueryCloud {
  std::vector<Eigen::Vector3f> points;   // metres, in the query's frame
  std::vector<Eigen::Vector3f> normals;  // unit, one per point, or empty
  std::vector<Rgb8> colors;              // one per point, or empty
  std::optional<Eigen::Vector3d> viewpoint;  // the sensor, in the same frame
};

// The segment (label 1, segment frame at its grid's lower corner, as the GSM's). Errors
// (INVALID_ARGUMENT, naming the field): images of the wrong size, a mask of the wrong size, a
// pose that is not rigid, no masked pixel with a depth in the TSDF's ray range.
StatusOr<gsm::RawSegment> segmentFromDepth(const QueryDepth& query, const TsdfParams& tsdf);
// Errors (INVALID_ARGUMENT, naming the field): no points, more than kMaxQueryPoints, a point or
// normal not finite, normals or colours not one per point, seen from a viewpoint: no point in the
// TSDF's ray range of it.
StatusOr<gsm::RawSegment> segmentFromCloud(const QueryCloud& query, const TsdfParams& tsdf);

}  // namespace objdb::database
