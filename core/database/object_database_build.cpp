// A model made of its segments. Each model is the fusion of its raw segments' grids in observation
// order (the first segment's frame is the model frame), its surface voxels the union of theirs
// (first seen first), its cloud, keypoints and descriptors built on that grid at the mean depth
// the segments were seen from. buildFromObservations fuses every segment (a withdrawal, a join of
// two models); extendModel fuses one more segment into a stored model's grid, which is that
// fusion already, so that a merge costs one segment's fusion and not one per segment the model
// holds.
#include <utility>

#include "absl/container/flat_hash_set.h"
#include "core/common/grid_key.h"
#include "core/database/object_database.h"
#include "core/matching/verification.h"

namespace objdb::database {
namespace {

// The grid and surface voxels of segments fused in order.
class Fusion {
 public:
  Fusion() = default;
  // Starts from a model's grid and voxels: the fusion of its segments so far.
  explicit Fusion(const model::ObjectModel& model)
      : grid_(model.grid.clone()), voxels_(model.surface_voxels) {
    for (const auto& v : voxels_) seen_.insert(packGridKey(v));
  }

  Status add(const tsdf::TsdfLayer& segment_grid, const std::vector<tsdf::VoxelIndex>& voxels,
             const Transform& T_object_segment, float max_weight) {
    if (!grid_) {
      OBJDB_ASSIGN_OR_RETURN(
          tsdf::TsdfLayer empty,
          tsdf::TsdfLayer::create(segment_grid.voxelSize(), segment_grid.voxelsPerSide()));
      grid_.emplace(std::move(empty));
    }
    matching::mergeGrids(&*grid_, segment_grid, T_object_segment, max_weight);
    const Eigen::Isometry3f T = T_object_segment.cast<float>();
    for (const auto& v : voxels) {
      const tsdf::VoxelIndex mapped = grid_->voxelIndexOf(T * segment_grid.voxelCenter(v));
      if (seen_.insert(packGridKey(mapped)).second) voxels_.push_back(mapped);
    }
    return absl::OkStatus();
  }

  tsdf::TsdfLayer takeGrid() { return std::move(*grid_); }
  std::vector<tsdf::VoxelIndex> takeVoxels() { return std::move(voxels_); }

 private:
  std::optional<tsdf::TsdfLayer> grid_;
  std::vector<tsdf::VoxelIndex> voxels_;
  absl::flat_hash_set<uint64_t> seen_;
};

// The surface is judged with the noise of the depths its segments were seen from: the mean of
// the known ones (0: none known), summed in observation order.
float meanKnownDepth(const std::vector<float>& depths) {
  double sum = 0.0;
  int known = 0;
  for (const float d : depths) {
    if (d > 0.0f) {
      sum += d;
      ++known;
    }
  }
  return known > 0 ? float(sum / known) : 0.0f;
}

// Fuses the segments of observations[first, end) into `fusion` in order, each read from `store`
// but `in_hand` (the segment being inserted, when it is one of them), and appends their depths.
Status fuseSegments(const ModelStore& store, const std::vector<model::Observation>& observations,
                    size_t first, const RawSegmentRecord* in_hand, float max_weight, Fusion* fusion,
                    std::vector<float>* depths) {
  for (size_t i = first; i < observations.size(); ++i) {
    const model::Observation& o = observations[i];
    std::shared_ptr<const RawSegmentRecord> read;
    const RawSegmentRecord* segment = in_hand;
    if (in_hand == nullptr || !(in_hand->key == keyOf(o))) {
      OBJDB_ASSIGN_OR_RETURN(read, store.rawSegment(keyOf(o)));
      segment = read.get();
    }
    depths->push_back(segment->observation_depth_m);
    OBJDB_RETURN_IF_ERROR(
        fusion->add(*segment->grid, segment->voxels, o.T_object_segment, max_weight));
  }
  return absl::OkStatus();
}

// The model on the fused grid and voxels (`build` at the segments' mean known depth).
StatusOr<model::ObjectModel> modelOf(Fusion* fusion, std::vector<model::Observation> observations,
                                     int64_t id, const model::ModelBuildParams& build) {
  OBJDB_ASSIGN_OR_RETURN(model::ObjectModel model,
                         model::buildModel(fusion->takeGrid(), fusion->takeVoxels(), build));
  model.id = id;
  model.observations = std::move(observations);
  return model;
}

}  // namespace

StatusOr<model::ObjectModel> ObjectDatabase::buildFromObservations(
    std::vector<model::Observation> observations, int64_t id) {
  if (observations.empty()) return absl::InternalError("a model needs an observation");
  Fusion fusion;
  std::vector<float> depths;
  OBJDB_RETURN_IF_ERROR(
      fuseSegments(*store_, observations, 0, nullptr, params_.tsdf.max_weight, &fusion, &depths));
  return modelOf(&fusion, std::move(observations), id, buildParams(meanKnownDepth(depths)));
}

StatusOr<model::ObjectModel> ObjectDatabase::extendModel(
    const model::ObjectModel& target, std::vector<model::Observation> observations,
    const RawSegmentRecord* in_hand, size_t* fused) {
  const size_t own = target.observations.size();
  if (observations.size() <= own) return absl::InternalError("a model extended by no segment");
  // A model of one segment holds that segment's grid as it was extracted, which is not quite its
  // fusion into an empty grid (resampling drops voxels whose interpolation lacks a corner): it is
  // rebuilt from all the segments, as every model of several segments was. (Were the model stored
  // with another tsdf.max_weight, its grid keeps the old cap; the new segments are fused with the
  // current one.)
  if (own < 2) {
    *fused = observations.size();
    return buildFromObservations(std::move(observations), target.id);
  }
  std::vector<SegmentKey> keys;
  keys.reserve(own);
  for (size_t i = 0; i < own; ++i) keys.push_back(keyOf(observations[i]));
  OBJDB_ASSIGN_OR_RETURN(std::vector<float> depths, store_->observationDepths(keys));
  Fusion fusion(target);
  OBJDB_RETURN_IF_ERROR(
      fuseSegments(*store_, observations, own, in_hand, params_.tsdf.max_weight, &fusion, &depths));
  *fused = observations.size() - own;
  return modelOf(&fusion, std::move(observations), target.id, buildParams(meanKnownDepth(depths)));
}

}  // namespace objdb::database
