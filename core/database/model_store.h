// What the object database needs from storage (paper §III-C, Algorithm 1's Ω): raw segments
// keyed by (session, GSM label), object models, merge records and the scene map of each session
// (for model-to-scene verification). Every mutating call is one unit — the SQLite store
// makes each a transaction. InMemoryModelStore serves tests and offline benchmarks.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "core/common/transform.h"
#include "core/gsm/gsm.h"
#include "core/model/object_model.h"
#include "core/tsdf/tsdf_layer.h"

namespace objdb::database {

struct SegmentKey {
  std::string session;
  uint32_t label = 0;  // GSM label
  auto operator<=>(const SegmentKey&) const = default;
};
// The raw segment an observation of a model is.
inline SegmentKey keyOf(const model::Observation& o) { return {o.session, o.label}; }

// A raw segment as the database keeps it: its grid in its own frame and where that frame is.
struct RawSegmentRecord {
  SegmentKey key;
  Transform T_world_segment = Transform::Identity();
  std::shared_ptr<const tsdf::TsdfLayer> grid;
  std::vector<tsdf::VoxelIndex> voxels;  // the label's voxels, segment frame
  int64_t extraction_frame = 0;
  float observation_depth_m = 0.0f;      // RawSegment::observation_depth_m (0: unknown)
  std::vector<uint32_t> parts;           // RawSegment::parts: the object's GSM labels, sorted
  std::vector<uint32_t> voxel_parts;     // RawSegment::voxel_parts: each voxel's part (empty: none)
};

// Evidence of one merge (the numbers the verification produced), persisted with it.
struct MergeRecord {
  int64_t target = 0;  // model that absorbed
  std::string source;  // what was merged in: "segment <session>/<label>" or "model <id>"
  Transform T_target_source = Transform::Identity();
  double icp_rmse_m = 0.0;
  double tsdf_rmse_m = 0.0;
  size_t tsdf_overlap = 0;
  size_t scene_checks = 0;  // model-to-scene verifications passed
};

// One model as the prefilter sees it.
struct MatchEntry {
  int64_t id = 0;
  bool planar = false;
  bool structure = false;
  size_t num_points = 0;
  size_t num_keypoints = 0;
  std::vector<model::Fpfh> descriptors;
  // model::globalDescriptor of the descriptors (empty when it has none, or when the store's is
  // missing or of another codebook version): the short list's key.
  std::vector<float> global;
  // Read without its local descriptors (ModelStore::matchEntries(false)): `descriptors` is empty
  // and matchable() takes them to be one per keypoint, as every stored model with descriptors has.
  bool descriptors_omitted = false;
  std::vector<SegmentKey> segments;  // the raw segments it holds (its observations)
  // The same rule as ObjectModel::matchable.
  bool matchable(const ModelParams& params) const;
};

struct MatchEntries {
  std::vector<MatchEntry> entries;  // ascending id
  std::vector<Status> skipped;      // models that could not be read, with the reason
};

MatchEntry matchEntryOf(const model::ObjectModel& model);

// The exclusive right to change a shared store's models, held while it lives
// (ModelStore::lockWriter).
class WriterLock {
 public:
  virtual ~WriterLock() = default;
};

// What other writers changed in a shared store (ModelStore::modelChangesSince).
struct ModelChanges {
  int64_t seq = 0;                  // the store's change sequence after these changes
  std::vector<MatchEntry> entries;  // models changed that are active now, ascending id
  std::vector<int64_t> retired;     // models changed that are no longer active (merged, removed)
  std::vector<Status> skipped;      // changed models that could not be read, with the reason
};

class ModelStore {
 public:
  virtual ~ModelStore() = default;

  // Several writers on one store (several servers on one PostgreSQL database): every change to
  // the models happens under the writer lock, which the store hands to one writer at a time
  // across every process; each change advances the store's change sequence, and a writer that
  // takes the lock catches up on the changes since its last (modelChangesSince) before it
  // matches. A store with one writer (the defaults, SQLite: one process owns the file) returns
  // no lock, and a writer's own changes are all there are.
  virtual StatusOr<std::unique_ptr<WriterLock>> lockWriter() {
    return std::unique_ptr<WriterLock>();
  }
  // The change sequence now (read under the writer lock: the last change made).
  virtual StatusOr<int64_t> modelChangeSeq() const { return int64_t{0}; }
  // The models changed after sequence number `seq`.
  virtual StatusOr<ModelChanges> modelChangesSince(int64_t seq) const {
    ModelChanges none;
    none.seq = seq;
    return none;
  }

  // Stores a raw segment, replacing an earlier one with the same key.
  virtual Status putRawSegment(const RawSegmentRecord& segment) = 0;
  virtual StatusOr<std::shared_ptr<const RawSegmentRecord>> rawSegment(
      const SegmentKey& key) const = 0;
  // The depth each of these raw segments was seen from (RawSegmentRecord::observation_depth_m;
  // 0: unknown), in their order. A merge into a model of many segments needs all their depths but
  // the grid of the new segment only; a backend answers this without decoding grids. NOT_FOUND:
  // a key without a raw segment. This default reads the whole records.
  virtual StatusOr<std::vector<float>> observationDepths(const std::vector<SegmentKey>& keys) const;

  // Adds a model; the store assigns and returns its id (stable, never reused).
  virtual StatusOr<int64_t> addModel(model::ObjectModel model) = 0;
  // Replaces model `model.id`; with a merge record in the same unit when given.
  virtual Status replaceModel(model::ObjectModel model,
                              const std::optional<MergeRecord>& merge) = 0;
  // Model `absorbed` merged into model `target.id`, in one unit: `target` (holding both models'
  // observations) replaces the stored model, `merge` is recorded, and `absorbed` leaves the
  // active models (kept as merged into target.id where the store keeps lineage).
  virtual Status absorbModel(model::ObjectModel target, const MergeRecord& merge,
                             int64_t absorbed) = 0;
  virtual Status removeModel(int64_t id) = 0;
  // Where the segment of the removed model `removed` went: the model `successor` holds it now (a
  // re-extracted segment that emptied its old model). Kept where the store keeps lineage (the
  // tombstone's merged_into), so that a query of the removed id can say where to look; this
  // default keeps nothing.
  virtual Status setSuccessor(int64_t removed, int64_t successor) {
    (void)removed;
    (void)successor;
    return Status();
  }
  virtual StatusOr<std::shared_ptr<const model::ObjectModel>> model(int64_t id) const = 0;
  // Ids of the stored (active) models, ascending.
  virtual StatusOr<std::vector<int64_t>> modelIds() const = 0;
  // What the matcher's prefilter needs of every active model, without grids and clouds. Models
  // whose data cannot be read are left out and named in `skipped`. `descriptors` false: without
  // the local descriptors (a database with a short list opens on the global ones and reads the
  // local ones of its short list per insert, descriptorsOf).
  virtual StatusOr<MatchEntries> matchEntries(bool descriptors) const = 0;
  // The local descriptors of models `ids`, in that order, and nothing else of them. NOT_FOUND
  // for an id the store does not hold. This default decodes each whole model.
  virtual StatusOr<std::vector<std::vector<model::Fpfh>>> descriptorsOf(
      const std::vector<int64_t>& ids) const;
  // Keeps global descriptors computed for stored models whose own was missing or of another
  // codebook version (model::kCodebookVersion), so that the next opening reads them. Not a
  // change of the models (other writers are not told). This default keeps nothing.
  virtual Status putGlobalDescriptors(
      const std::vector<std::pair<int64_t, std::vector<float>>>& globals) {
    (void)globals;
    return Status();
  }
  virtual StatusOr<std::vector<MergeRecord>> mergeRecords() const = 0;

  // Stores the scene map of a session (its TSDF and, when given, the GSM's main label of every
  // voxel), replacing an earlier one.
  virtual Status putScene(const std::string& session, std::shared_ptr<const tsdf::TsdfLayer> scene,
                          std::shared_ptr<const gsm::LabelBlocks> labels = nullptr) = 0;
  // The scene map of a session (null when the session has none).
  virtual StatusOr<std::shared_ptr<const tsdf::TsdfLayer>> scene(
      const std::string& session) const = 0;
  // Its labels (null when none were stored).
  virtual StatusOr<std::shared_ptr<const gsm::LabelBlocks>> sceneLabels(
      const std::string& session) const = 0;
};

class InMemoryModelStore : public ModelStore {
 public:
  Status putRawSegment(const RawSegmentRecord& segment) override;
  StatusOr<std::shared_ptr<const RawSegmentRecord>> rawSegment(
      const SegmentKey& key) const override;
  StatusOr<int64_t> addModel(model::ObjectModel model) override;
  Status replaceModel(model::ObjectModel model, const std::optional<MergeRecord>& merge) override;
  Status absorbModel(model::ObjectModel target, const MergeRecord& merge,
                     int64_t absorbed) override;
  Status removeModel(int64_t id) override;
  StatusOr<std::shared_ptr<const model::ObjectModel>> model(int64_t id) const override;
  StatusOr<std::vector<int64_t>> modelIds() const override;
  StatusOr<MatchEntries> matchEntries(bool descriptors) const override;
  StatusOr<std::vector<MergeRecord>> mergeRecords() const override;
  Status putScene(const std::string& session, std::shared_ptr<const tsdf::TsdfLayer> scene,
                  std::shared_ptr<const gsm::LabelBlocks> labels = nullptr) override;
  StatusOr<std::shared_ptr<const tsdf::TsdfLayer>> scene(
      const std::string& session) const override;
  StatusOr<std::shared_ptr<const gsm::LabelBlocks>> sceneLabels(
      const std::string& session) const override;

 private:
  mutable std::mutex mutex_;
  std::map<SegmentKey, std::shared_ptr<const RawSegmentRecord>> segments_;
  std::map<int64_t, std::shared_ptr<const model::ObjectModel>> models_;
  std::vector<MergeRecord> merges_;
  std::map<std::string, std::shared_ptr<const tsdf::TsdfLayer>> scenes_;
  std::map<std::string, std::shared_ptr<const gsm::LabelBlocks>> scene_labels_;
  int64_t next_id_ = 1;
};

}  // namespace objdb::database
