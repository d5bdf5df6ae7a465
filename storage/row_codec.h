// What both backends of storage::Store do the same way with a row's values (storage/sqlite/,
// storage/postgres/): result rows read into sessions, model summaries, merge records and match
// entries, a model encoded into its columns outside any lock, a model and a raw segment decoded
// from their columns with every cross-check, a map encoded into per-block blobs, the parts list,
// the blob columns the full check decodes, row-annotated errors, and the bounded cache of decoded
// scene maps.
#pragma once

#include <cstdint>
#include <functional>
#include <list>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "core/common/status.h"
#include "core/database/model_store.h"
#include "core/gsm/gsm.h"
#include "core/model/object_model.h"
#include "core/tsdf/tsdf_layer.h"
#include "storage/blob_codec.h"
#include "storage/store.h"

namespace objdb::storage {

// Blob errors keep their code (DATA_LOSS) and gain the row they sit in.
Status inRow(const Status& status, std::string_view table, int64_t row, std::string_view column);

// raw_segments.parts: GSM labels, comma-separated ("" = none recorded). Anything else is damage.
std::string formatParts(const std::vector<uint32_t>& parts);
StatusOr<std::vector<uint32_t>> parseParts(const std::string& text);

// The models columns a model's encoding fills, in the order both backends bind them, and the
// models columns StoreStats counts blob bytes of, as SQL both engines read (SQLite matches
// names case-insensitively, PostgreSQL folds them to lowercase).
inline constexpr const char* kModelColumns =
    "planar, plane_inlier_ratio, num_points, num_keypoints, voxel_size, bbox_min_x, bbox_min_y, "
    "bbox_min_z, bbox_max_x, bbox_max_y, bbox_max_z, grid, surface_voxels, cloud, keypoints, "
    "descriptors, cloud_ms, planarity_ms, keypoints_ms, descriptors_ms, structure, "
    "global_descriptor";
inline constexpr int kNumModelColumns = 22;

// The tables StoreStats lists, each with the SQL expression of one row's blob bytes.
struct StatsTable {
  const char* table;
  const char* blob_bytes;
};
const std::vector<StatsTable>& statsTables();

// One result row of either engine (SqliteStore: a statement's current row; PostgresStore: a row
// of a result), read by column (0-based) by the readers below. A view from bytes() is valid while
// the row is.
class Row {
 public:
  virtual bool isNull(int column) const = 0;
  virtual int64_t integer(int column) const = 0;  // booleans 0 or 1; NULL 0
  virtual double real(int column) const = 0;
  virtual std::string text(int column) const = 0;
  virtual std::string_view bytes(int column) const = 0;

 protected:
  ~Row() = default;
};

// Rows of both engines' queries, each read from the columns its SELECT list names (the same SQL
// in both engines).
inline constexpr const char* kSessionColumns =
    "id, name, intrinsics, params, started_at, COALESCE(ended_at, ''), state, frames, client, "
    "counters";
SessionInfo readSession(const Row& row);
// Of sessions s: 1 when a row refers to the session (a raw segment, an observation, its scene),
// which then cannot be deleted (Store::retireSession).
inline constexpr const char* kSessionReferred =
    "CASE WHEN EXISTS (SELECT 1 FROM raw_segments r WHERE r.session_id = s.id) OR "
    "EXISTS (SELECT 1 FROM observations o WHERE o.session_id = s.id) OR "
    "EXISTS (SELECT 1 FROM scene_maps m WHERE m.session_id = s.id) THEN 1 ELSE 0 END";
// Of models m; without observations.
inline constexpr const char* kModelSummaryColumns =
    "m.id, m.state, COALESCE(m.merged_into, 0), m.planar, m.num_points, m.num_keypoints, "
    "COALESCE(m.voxel_size, 0), COALESCE(m.bbox_min_x, 0), COALESCE(m.bbox_min_y, 0), "
    "COALESCE(m.bbox_min_z, 0), COALESCE(m.bbox_max_x, 0), COALESCE(m.bbox_max_y, 0), "
    "COALESCE(m.bbox_max_z, 0), (SELECT COUNT(*) FROM merge_records r WHERE r.target = m.id), "
    "m.structure";
ModelSummary readModelSummary(const Row& row);
// DATA_LOSS for a damaged transform.
inline constexpr const char* kMergeRecordColumns =
    "id, target, source, transform, icp_rmse_m, tsdf_rmse_m, tsdf_overlap, scene_checks";
StatusOr<database::MergeRecord> readMergeRecord(const Row& row);
// Without segments. DATA_LOSS naming the row for damaged descriptors (`entry->id` is set then
// too). A global descriptor of another codebook version (or none) leaves `global` empty.
inline constexpr const char* kMatchEntryColumns =
    "id, planar, num_points, num_keypoints, descriptors, structure, global_descriptor";
// The same without the local descriptors (a database with a short list opens on these).
inline constexpr const char* kMatchEntryColumnsWithoutDescriptors =
    "id, planar, num_points, num_keypoints, NULL, structure, global_descriptor";
Status readMatchEntry(const Row& row, database::MatchEntry* entry);

// A model's columns (the models row and its observation rows), encoded.
struct EncodedModel {
  bool planar = false;
  bool structure = false;
  double plane_inlier_ratio = 0;
  int64_t num_points = 0, num_keypoints = 0;
  double voxel_size = 0;
  Eigen::Vector3f bbox_min = Eigen::Vector3f::Zero(), bbox_max = Eigen::Vector3f::Zero();
  std::string grid, surface_voxels, cloud, keypoints, descriptors;
  model::BuildTimings timings;
  std::string global_descriptor;  // its blob; empty (NULL) for a model without descriptors
  struct Obs {
    std::string session;
    int64_t label;
    std::string T_world_object, T_object_segment;
  };
  std::vector<Obs> observations;
};
EncodedModel encodeModel(const model::ObjectModel& m, const BlobOptions& options);

// A models row as read: its scalars and its blobs (views into the engine's result).
struct ModelColumns {
  bool planar = false, structure = false;
  double plane_inlier_ratio = 0;
  std::string_view grid, surface_voxels, cloud, keypoints, descriptors;
  model::BuildTimings timings;
};
// The columns of a row of kModelColumns.
ModelColumns readModelColumns(const Row& row);
// Model `id` from its columns (without observations); DATA_LOSS naming the column of a damaged
// blob, or keypoints and descriptors that do not fit the cloud.
StatusOr<model::ObjectModel> decodeModel(int64_t id, const ModelColumns& columns);

// One observation row as read.
struct ObservationColumns {
  int64_t row = 0;  // its row id (for messages)
  std::string session;
  int64_t label = 0;
  std::string_view T_world_object, T_object_segment;
};
StatusOr<model::Observation> decodeObservation(const ObservationColumns& columns);

// A raw segment's columns, encoded; INVALID_ARGUMENT for a segment without a grid or with voxel
// parts that do not align with its voxels.
struct EncodedRawSegment {
  std::string pose, grid, voxels;
  std::optional<std::string> voxel_parts;  // absent: none recorded
  std::string parts;                       // formatParts
};
StatusOr<EncodedRawSegment> encodeRawSegment(const database::RawSegmentRecord& segment,
                                             const BlobOptions& options);

// A raw_segments row as read.
struct RawSegmentColumns {
  int64_t row = 0;
  std::string_view pose, grid, voxels;
  int64_t extraction_frame = 0;
  double observation_depth_m = 0;
  std::string parts;
  std::optional<std::string_view> voxel_parts;
};
// The columns of a row of kRawSegmentColumns (of raw_segments r).
inline constexpr const char* kRawSegmentColumns =
    "r.id, r.pose, r.grid, r.voxels, r.extraction_frame, r.observation_depth_m, r.parts, "
    "r.voxel_parts";
RawSegmentColumns readRawSegmentColumns(const Row& row);
// A segment's parts invariant: `voxel_parts` is empty (none recorded) or holds one part per voxel,
// each of them one of `parts`. The message names the first offence ("a voxel of part 3, which is
// not one of its parts 1, 2"); the caller chooses the code (writing: INVALID_ARGUMENT, reading:
// DATA_LOSS).
std::string segmentPartsOffence(const std::vector<uint32_t>& parts,
                                const std::vector<uint32_t>& voxel_parts, size_t voxels);
// The same on a stored row's columns (parts, voxels, voxel_parts), as `objdb db check` reads
// them: the column at fault and what is wrong with it (a column that does not decode, or the
// invariant), or nothing when they agree.
struct ColumnOffence {
  std::string column, message;
};
std::optional<ColumnOffence> rawSegmentPartsOffence(const std::string& parts,
                                                    std::string_view voxels,
                                                    std::string_view voxel_parts);
// The columns rawSegmentPartsOffence reads (the row id first) of the raw_segments rows with voxel
// parts recorded, in id order (SQL both engines read).
inline constexpr const char* kRawSegmentPartsQuery =
    "SELECT id, parts, voxels, voxel_parts FROM raw_segments WHERE voxel_parts IS NOT NULL "
    "ORDER BY id";
StatusOr<std::shared_ptr<const database::RawSegmentRecord>> decodeRawSegment(
    const database::SegmentKey& key, const RawSegmentColumns& columns);

// A map's blocks as blobs (`what` names it in messages: "scene of session s1").
struct EncodedBlock {
  tsdf::BlockIndex index;
  std::string blob;
};
struct EncodedMap {
  double voxel_size = 0;
  int64_t voxels_per_side = 0;
  std::vector<EncodedBlock> tsdf, labels;
};
// INVALID_ARGUMENT when a label block's size is not the grid's block size.
StatusOr<EncodedMap> encodeMap(const std::string& what, const tsdf::TsdfLayer& map,
                               const gsm::LabelBlocks* labels, const BlobOptions& options);
// One label block of a map, encoded; INVALID_ARGUMENT (naming `what` and the block) when its
// size is not the grid's block size.
StatusOr<EncodedBlock> encodeMapLabels(const std::string& what, const tsdf::BlockIndex& index,
                                       const std::vector<uint32_t>& labels,
                                       int64_t voxels_per_side, const BlobOptions& options);
// A label block as read (`where` names it in messages); DATA_LOSS when damaged or of another size.
StatusOr<std::vector<uint32_t>> decodeMapLabels(std::string_view blob, int64_t voxels_per_side,
                                                const std::string& where);
// An empty map of the stored geometry; DATA_LOSS when it is no valid layer.
StatusOr<tsdf::TsdfLayer> emptyMap(const std::string& what, double voxel_size,
                                   int64_t voxels_per_side);

// The blob columns the full check decodes (table, column, decoder); map TSDF blocks, which need
// their map's block size, are checked apart (checkTsdfBlock).
struct BlobColumn {
  const char* table;
  const char* column;
  std::function<Status(std::string_view)> decode;
};
const std::vector<BlobColumn>& checkedBlobColumns();
// A map block's TSDF blob against its map's block size.
Status checkTsdfBlock(std::string_view blob, int64_t voxels_per_side);

// The decoded scene maps (TSDF and labels per session), most recently used first, at most
// `max_entries` sessions each. Thread-safe.
class SceneCache {
 public:
  explicit SceneCache(size_t max_entries) : max_entries_(max_entries) {}
  std::optional<std::shared_ptr<const tsdf::TsdfLayer>> scene(const std::string& session);
  std::optional<std::shared_ptr<const gsm::LabelBlocks>> labels(const std::string& session);
  void putScene(const std::string& session, std::shared_ptr<const tsdf::TsdfLayer> scene);
  void putLabels(const std::string& session, std::shared_ptr<const gsm::LabelBlocks> labels);

 private:
  template <typename Value>
  using Entries = std::list<std::pair<std::string, Value>>;
  template <typename Value>
  std::optional<Value> get(Entries<Value>* cache, const std::string& key);
  template <typename Value>
  void put(Entries<Value>* cache, const std::string& key, Value value);

  const size_t max_entries_;
  std::mutex mutex_;
  Entries<std::shared_ptr<const tsdf::TsdfLayer>> scenes_;
  Entries<std::shared_ptr<const gsm::LabelBlocks>> labels_;
};

}  // namespace objdb::storage
