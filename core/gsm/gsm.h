// Global Segmentation Map (paper §III-B): a TSDF layer plus a label layer of the same block
// structure whose voxels keep a bounded history of label votes (label_voxel.h). Each frame's
// segments are associated with global labels by counting, over the voxels their points fall
// into, how often each existing main label appears; labels that keep co-occurring inside one
// segment are merged (union–find: O(1), counts summed lazily, lossless); labels untouched for
// a while are extracted as raw segments for the object database.
#pragma once

#include <functional>

#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <vector>

#include <Eigen/Geometry>

#include "absl/container/flat_hash_map.h"
#include "absl/container/flat_hash_set.h"
#include "core/common/params.h"
#include "core/gsm/label_voxel.h"
#include "core/gsm/objects.h"
#include "core/gsm/surface_noise.h"
#include "core/segmentation/depth_segmenter.h"
#include "core/tsdf/tsdf_integrator.h"

namespace objdb::gsm {

// A finished segment: its label, its voxels' TSDF in its own frame and where that frame is.
struct RawSegment {
  Label label = 0;
  // Segment frame = world frame translated to the voxel-aligned lower corner of the grid, so
  // grid voxel centres coincide with the map's: p_world = T_world_segment * p_segment.
  Transform T_world_segment = Transform::Identity();
  tsdf::TsdfLayer grid;                      // voxels carrying the label plus a truncation margin
  std::vector<tsdf::VoxelIndex> label_voxels; // in the segment frame
  int64_t last_update_frame = 0;
  int64_t extraction_frame = 0;
  // Median distance of its voxels from the camera of its last update, metres (0: unknown, e.g.
  // a segment of a saved map): sets the depth noise its surface is judged with (planarity and
  // structure, core/model/structure.h).
  float observation_depth_m = 0.0f;
  // The GSM labels the segment is made of (core/gsm/objects.h): a whole object's parts, or just
  // `label` when the GSM extracts labels alone (GsmParams::objects false). Sorted.
  std::vector<Label> parts;
  // The part (GSM label, one of `parts`) of each of label_voxels, aligned with it; empty when not
  // recorded (a segment stored before parts had geometry).
  std::vector<Label> voxel_parts;
  // The session's measured depth-noise scale when the segment was extracted (SurfaceNoise::scale;
  // 0: unknown, e.g. too few frames yet or a segment of a saved map).
  float noise_scale = 0.0f;
  // The room structure's verdict on it (core/gsm/objects.h, ObjectGroups::structure): true when
  // it is a structure label (a floor, wall or face piece, or a label larger than furniture),
  // false for an object. Unset when the GSM did not group objects (GsmParams::objects false): the
  // database then judges the segment itself.
  std::optional<bool> structure;
};

// Milliseconds spent per step of Gsm::integrate.
struct GsmTimings {
  double integration_ms = 0;  // TSDF (and carving)
  double association_ms = 0;  // points into voxels, segment × label overlaps, label choice, merges
  double voting_ms = 0;       // the per-voxel label votes
};

struct GsmFrameResult {
  tsdf::IntegrationStats tsdf;
  GsmTimings timings;
  std::vector<Label> segment_labels;  // global label of each frame segment (index = label − 1)
  size_t new_labels = 0;
  size_t merges = 0;
  size_t voted_voxels = 0;
};

struct LabelInfo {
  int64_t voxels = 0;             // voxels whose (raw) main label is this label or a merged one
  int64_t last_update_frame = -1;
  int64_t frames = 0;             // frames that voted for it (of merged labels, the most)
  int64_t extracted_frame = -1;   // −1: not extracted since its last update
  // Voxels at its last extraction (0: never extracted, or withdrawn since). Re-extracting a label
  // that lost a fifth of them to other labels (its stored segment out of date) was tried: on the
  // lounge through the server it cost 8 points of recall (36 % against 44 %) for 50 % more
  // inserts, so only merged-away and vanished labels are withdrawn (takeWithdrawn).
  int64_t extracted_voxels = 0;
  Eigen::AlignedBox3i bounds;     // voxel indices that ever got a vote for it (empty at first)
  absl::flat_hash_set<tsdf::BlockIndex, tsdf::BlockIndexHash> blocks;  // where it has votes
};

// What the object extraction did (GsmParams::objects), counted over the session.
struct ExtractionCounts {
  size_t first = 0;        // objects extracted for the first time (or again after a withdrawal)
  size_t again = 0;        // extracted again: updated, and changed by reextract_min_change or more
  size_t unchanged = 0;    // updated but changed less: the earlier segment stands
  size_t unconfirmed = 0;  // idle objects held back: no label seen in object_min_frames frames
  size_t withdrawn = 0;    // extracted objects withdrawn (went into another, or vanished)
};

// LabelBlocks (objects.h): the main label (after merges; 0 = none) of every voxel of each label
// block, in the block's voxel order: the labels of a scene map as the store keeps them.

// The raw segment of `label` made of `voxels` (map voxel indices): their TSDF plus `margin`
// voxels around them, in the segment frame (see RawSegment). `part_of` gives the part (GSM label)
// of a map voxel, for RawSegment::voxel_parts; without it every voxel is of `label`.
RawSegment extractRawSegment(const tsdf::TsdfLayer& layer, Label label,
                             std::vector<tsdf::VoxelIndex> voxels, int margin,
                             int64_t last_update_frame, int64_t frame,
                             const std::function<Label(const tsdf::VoxelIndex&)>& part_of = {});

// Every object (params.objects) or label of a stored map (its TSDF and main labels) with at
// least params.min_label_voxels voxels as a raw segment, in id order, as the GSM would extract
// them at the end of its session (used to end a session from its saved map, without its label
// histories).
std::vector<RawSegment> extractLabelled(const tsdf::TsdfLayer& layer, const LabelBlocks& labels,
                                        const GsmParams& params, int margin, int64_t frame);

class Gsm {
 public:
  static StatusOr<Gsm> create(const TsdfParams& tsdf_params, const GsmParams& gsm_params,
                              const Intrinsics& intrinsics, int threads = 1);
  Gsm(Gsm&&) noexcept;
  Gsm& operator=(Gsm&&) noexcept;
  ~Gsm();

  // Fuses one segmented frame: `labels` are the frame's segment labels per pixel (0 = none), as
  // DepthSegmenter produces. Errors leave the map unchanged.
  StatusOr<GsmFrameResult> integrate(const DepthImage& depth, const segmentation::LabelImage& labels,
                                     const Transform& T_world_camera,
                                     const ColorImage* color = nullptr);

  // Raw segments of the labels not updated for extraction_age_frames frames (all labels when
  // `flush`), each extracted once until it is updated again; labels smaller than
  // min_label_voxels are skipped. With GsmParams::objects, of the objects instead (objects.h),
  // regrouped every object_update_frames frames: an object is extracted when all its parts are
  // idle, and again when a part was updated or its parts changed.
  std::vector<RawSegment> extractIdle(bool flush = false);
  // The map's labels grouped into objects now (objects.h).
  ObjectGroups groupObjects() const;
  // The cameras' mean image up (world; unit), or zero when the frames so far do not agree on one
  // (their mean is shorter than half a unit: a camera rolled over, or no frame yet).
  Eigen::Vector3f upHint() const;
  // Labels (objects) extracted before whose segment no longer exists: merged into another label (whose
  // next extraction holds their voxels), or updated and then left with fewer than
  // min_label_voxels voxels because other labels took them. Whoever keeps the extracted segments drops these (otherwise one
  // surface would be kept twice, under its old and its new label). Returned once, then cleared.
  std::vector<Label> takeWithdrawn();

  const ExtractionCounts& extractionCounts() const { return extraction_counts_; }

  // The label a (possibly merged-away) label now belongs to.
  Label resolve(Label label) const;
  // Main label of a voxel after merges (0 = none or unallocated).
  Label mainLabel(const tsdf::VoxelIndex& v) const;
  // mainLabel of every voxel, block by block (blocks without any label are left out).
  LabelBlocks mainLabelBlocks() const;
  const LabelVoxel* labelVoxel(const tsdf::VoxelIndex& v) const;

  const tsdf::TsdfLayer& tsdf() const { return layer_; }
  tsdf::TsdfLayer& tsdf() { return layer_; }
  int64_t frames() const { return frame_; }
  size_t numLabels() const { return info_.size(); }
  const absl::flat_hash_map<Label, LabelInfo>& labels() const { return info_; }
  size_t labelBytes() const;
  // The σ(z) model the session's depth noise is measured against (surface_noise.h; ModelParams'
  // noise fields, their defaults until set).
  void setNoiseModel(const ModelParams& model) { surface_noise_ = SurfaceNoise(model); }

 private:
  Gsm(const TsdfParams& tsdf_params, const GsmParams& gsm_params, tsdf::TsdfIntegrator integrator,
      tsdf::TsdfLayer layer);
  Label newLabel();
  void merge(Label keep, Label gone);
  Label mainOf(const LabelVoxel& voxel) const;
  std::vector<RawSegment> extractIdleLabels(bool flush);
  std::vector<RawSegment> extractIdleObjects(bool flush);
  // The voxels whose main label is in `labels` (sorted), found through their block indices.
  std::vector<tsdf::VoxelIndex> voxelsOf(const std::vector<Label>& labels) const;
  // Median distance of `voxels` from the camera of frame `frame` (0: unknown frame).
  float observationDepth(const std::vector<tsdf::VoxelIndex>& voxels, int64_t frame) const;
  struct FrameScratch;  // per-frame votes grouped by block, reused between frames

  TsdfParams tsdf_params_;
  GsmParams params_;
  Intrinsics intrinsics_;
  tsdf::TsdfIntegrator integrator_;
  tsdf::TsdfLayer layer_;
  absl::flat_hash_map<tsdf::BlockIndex, std::vector<LabelVoxel>, tsdf::BlockIndexHash> label_blocks_;
  absl::flat_hash_map<Label, LabelInfo> info_;          // roots only
  std::vector<Label> parent_ = {0};  // union–find over all labels ever made (index = label)
  // Per touching label pair (a, b packed): frames in which one segment covered both (merge
  // evidence) and frames in which each was claimed by a segment of its own.
  struct PairEvidence {
    int joint = 0, separate = 0;
  };
  absl::flat_hash_map<uint64_t, PairEvidence> pair_evidence_;
  std::vector<Label> withdrawn_;  // see takeWithdrawn()
  // Objects extracted (id → its parts then, its voxels (packGridKey, sorted) and the frame):
  // extracted again when they were updated since and the voxels changed enough
  // (GsmParams::reextract_min_change).
  struct ExtractedObject {
    std::vector<Label> parts;
    std::vector<uint64_t> voxels;
    int64_t frame = -1;
  };
  ExtractionCounts extraction_counts_;
  absl::flat_hash_set<Label> unconfirmed_;  // objects held back once as flicker (counted)
  absl::flat_hash_map<Label, ExtractedObject> extracted_objects_;
  int64_t grouped_frame_ = -1;  // the frame objects were last regrouped at
  ObjectGroups groups_;  // object id → parts (and annexed structure voxels), as then
  int64_t room_frame_ = -1;  // the frame the room structure in groups_ was found at
  Label next_label_ = 1;
  int64_t frame_ = 0;
  std::vector<Eigen::Vector3f> camera_positions_;  // world, one per integrated frame
  Eigen::Vector3d camera_up_sum_ = Eigen::Vector3d::Zero();  // Σ image up (−y) in the world
  SurfaceNoise surface_noise_;
  std::unique_ptr<FrameScratch> scratch_;
};

}  // namespace objdb::gsm
