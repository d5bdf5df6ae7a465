// Object models (paper §III-C.1–2): what the database stores per object. A model is built from a
// raw segment's TSDF grid: the zero level set inside the segment's voxels becomes a surface
// cloud with normals; a RANSAC plane test flags planar segments (stored, never matched); the
// rest get ISS + Harris3D keypoints and FPFH descriptors for matching.
//
// Frames: the grid, cloud and keypoints live in the model's own frame, the frame of its first
// raw segment; each observation says where that frame sat in a session's world.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "core/common/mesh.h"
#include "core/common/params.h"
#include "core/common/status.h"
#include "core/common/transform.h"
#include "core/tsdf/tsdf_layer.h"

namespace objdb::model {

using Fpfh = std::array<float, 33>;

// One observation of the object: a raw segment (session, GSM label) fused into the model, where
// the model frame was in that session's world, and where the segment's own frame sits in the
// model frame. The poses 𝕋 of the paper and the model's lineage in one list.
struct Observation {
  std::string session;
  uint32_t label = 0;
  Transform T_world_object = Transform::Identity();
  Transform T_object_segment = Transform::Identity();
};

// Two observations of one model are one placement when they are of one session and put the
// model's centre (model frame) within this of each other in the world: one surface under two GSM
// labels (the GSM split it, or kept a stale label), not a repeated object. Two objects cannot
// share a place.
inline constexpr double kSamePlaceM = 0.05;
bool samePlace(const std::string& session_a, const Transform& T_world_a,
               const std::string& session_b, const Transform& T_world_b,
               const Eigen::Vector3d& centre);
// Distinct placements among `poses` (session, T_world_object): each pose joins the first earlier
// one at its place.
size_t countPlaces(const std::vector<std::pair<std::string, Transform>>& poses,
                   const Eigen::Vector3d& centre);
// The centre those compare: the middle of the model cloud's bounding box (a stored model's
// bounds, storage::ModelSummary::bbox_min/max, give the same point). Zero for an empty cloud.
Eigen::Vector3d placeCentre(const PointCloud& cloud);

// Time spent building a model, ms (paper table II: P, K, D).
struct BuildTimings {
  double cloud_ms = 0, planarity_ms = 0, keypoints_ms = 0, descriptors_ms = 0;
};

struct ObjectModel {
  explicit ObjectModel(tsdf::TsdfLayer model_grid) : grid(std::move(model_grid)) {}

  int64_t id = 0;
  std::vector<Observation> observations;   // 𝕋 and lineage; the first defines the model frame
  tsdf::TsdfLayer grid;                    // model frame
  std::vector<tsdf::VoxelIndex> surface_voxels;  // the segments' voxels, model frame
  PointCloud cloud;                        // surface points + unit normals (outward), model frame
  std::vector<uint32_t> keypoint_indices;  // into cloud.points (ISS ∪ Harris3D)
  std::vector<Fpfh> descriptors;           // one per keypoint
  bool planar = false;                     // planar segments are stored, never matched
  bool structure = false;                  // room structure (structure.h): stored, never matched
  float plane_inlier_ratio = 0.0f;         // share of points on the best plane
  Eigen::Vector4f plane = Eigen::Vector4f::Zero();  // that plane (model frame; not stored)
  // The planes holding at least structure_min_share of the points, best first (SurfaceClass;
  // model frame; not stored): each is grown through the scene for the structure test.
  std::vector<Eigen::Vector4f> shared_planes;
  float plane_distance_m = 0.0f;           // the inlier distance it was found with (not stored)
  BuildTimings timings;

  // Matchable: neither planar nor structure, enough points, at least 3 described keypoints.
  bool matchable(const ModelParams& params) const;
  Eigen::Vector3f keypoint(size_t k) const { return cloud.points[keypoint_indices[k]]; }
};

// The matchable rule on a model's counts (ObjectModel::matchable, the prefilter's index entries).
bool isMatchable(bool planar_or_structure, size_t num_points, size_t num_keypoints,
                 size_t num_descriptors, const ModelParams& params);

// A deep copy (models are move-only: their grid owns its blocks).
ObjectModel cloneModel(const ObjectModel& model);

// Marching-tetrahedra surface of `grid` restricted to `voxels` (vertices whose nearest voxel is
// one of them), with area-weighted normals pointing out of the object (toward positive distance)
// and the grid's colours interpolated as its mesh has them (black where no colour was fused).
// Cells with a corner lighter than min_weight are skipped. Errors: no voxels given.
StatusOr<PointCloud> surfaceCloud(const tsdf::TsdfLayer& grid,
                                  const std::vector<tsdf::VoxelIndex>& voxels, float min_weight);

// One point per cube of side `spacing`: the mean of the points in it, with their mean normal
// (renormalised; cubes whose normals cancel out are dropped) and mean colour (when the cloud has
// colours). Deterministic order.
PointCloud resampleCloud(const PointCloud& cloud, float spacing);

struct ModelBuildParams {
  ModelParams model;
  KeypointParams keypoints;
  DescriptorParams descriptors;
  float mesh_min_weight = 3.0f;  // tsdf.mesh_min_weight
  int threads = 1;               // database.threads: keypoints and descriptors on this many
  // Depth the segment was seen from (RawSegment::observation_depth_m; 0 = unknown): the plane
  // distance of the planarity and structure tests follows the sensor noise there.
  float observation_depth_m = 0.0f;
  // Whether the segment is room structure, when decided elsewhere (RawSegment::structure, the
  // GSM's room structure): replaces the model's own structure test. Unset: that test decides.
  std::optional<bool> structure;
};

// What a segment makes: a model, or none when the segment cannot be one, with the reason. A
// segment is unusable when its voxels hold no surface at the mesh weight (no zero crossing
// observed often enough): a normal outcome of extraction, not an error.
struct SegmentModel {
  std::optional<ObjectModel> model;  // empty: unusable
  std::string unusable_reason;       // why, when `model` is empty
};

// Builds a model from a segment's grid and the voxels carrying its label (same frame; the grid
// becomes the model's), or says the segment is unusable. Errors: no voxels, invalid params.
StatusOr<SegmentModel> buildSegmentModel(tsdf::TsdfLayer grid,
                                         const std::vector<tsdf::VoxelIndex>& voxels,
                                         const ModelBuildParams& params);
// The same for callers that need a model (a merge's rebuild, tests): an unusable segment is
// FAILED_PRECONDITION with its reason.
StatusOr<ObjectModel> buildModel(tsdf::TsdfLayer grid, const std::vector<tsdf::VoxelIndex>& voxels,
                                 const ModelBuildParams& params);

}  // namespace objdb::model
