// The persistent object store (issue 6, DESIGN.md "Persistence"): core/database's ModelStore on
// one SQLite file in WAL mode. One writer connection (every mutation one BEGIN IMMEDIATE
// transaction), a pool of reader connections (every read one snapshot), binary data in
// checksummed, versioned, compressed blobs. A damaged blob fails only the row that holds it, with
// an error naming table, row and column. Sessions, scene maps (one row per TSDF block), raw
// segments, models, observations and merge records; `check()` and `stats()` for the admin CLI.
#pragma once

#include <list>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "core/common/intrinsics.h"
#include "core/database/model_store.h"
#include "storage/blob_codec.h"
#include "storage/schema.h"
#include "storage/sqlite_util.h"

namespace objdb::storage {

struct SqliteStoreOptions {
  bool create_if_missing = true;  // create an empty database when the file does not exist
  bool read_only = false;         // no writer connection; mutations fail with FAILED_PRECONDITION
  std::string synchronous = "FULL";  // FULL: commits survive power loss; NORMAL: survive
                                     // process crashes, may lose the last commits on power loss
  int busy_timeout_ms = 5000;     // how long a connection waits for a lock before UNAVAILABLE
  int64_t journal_size_limit_bytes = 64ll << 20;  // WAL file is truncated to this after checkpoints
  bool quick_check_on_open = true;  // PRAGMA quick_check before first use; corrupt → DATA_LOSS
  int max_readers = 8;            // reader connections kept open (more are opened on demand)
  // Decoded scene maps kept in memory (the most recently used; each a session's TSDF and labels,
  // ~0.05-0.1 GB for a room at 2 cm). Older ones are decoded again from the file when needed.
  int max_cached_scenes = 8;
  BlobOptions blobs;              // compression of new blobs
  Status validate() const;
};

// An open session's map as the server last saved it: its TSDF and main labels after `frames`
// frames. `map` is null when none is saved.
struct SavedMap {
  int64_t frames = 0;
  std::shared_ptr<const tsdf::TsdfLayer> map;
  std::shared_ptr<const gsm::LabelBlocks> labels;
};

// The tables of one kind of stored map: a session's scene map, or its saved live map.
struct MapTables {
  const char* what;  // in messages: "scene" or "saved map"
  const char* maps;
  const char* blocks;
  const char* label_blocks;
  bool has_frames;  // the map table has a `frames` column
};

struct BackupReport {
  int64_t pages = 0;
  int64_t bytes = 0;  // pages · page size
};

// Every store's hold on its database file, process-wide. One writer per file: a writable store
// takes an advisory lock (flock) on the file. POSIX drops a process's fcntl locks on a file —
// SQLite's — when any descriptor of that file is closed, so the process keeps one descriptor per
// file, shared by all its stores (read-only ones too), and closes it only when the last of them
// has closed its connections.
class FileRegistration {
 public:
  // Registers a store of `path` (which must exist); `writer`: also takes the writer lock.
  // FAILED_PRECONDITION when another writer (in this process or another) holds it.
  static StatusOr<FileRegistration> acquire(const std::string& path, bool writer);
  FileRegistration(FileRegistration&& other) noexcept;
  FileRegistration& operator=(FileRegistration&&) = delete;
  FileRegistration(const FileRegistration&) = delete;
  ~FileRegistration();

 private:
  FileRegistration(uint64_t device, uint64_t inode, bool writer)
      : device_(device), inode_(inode), writer_(writer), active_(true) {}
  uint64_t device_ = 0, inode_ = 0;
  bool writer_ = false;
  bool active_ = false;
};

enum class SessionState { kOpen, kEnded, kInterrupted };
const char* sessionStateName(SessionState state);

// SessionInfo::intrinsics_json of `intrinsics`: {"width", "height", "fx", "fy", "cx", "cy"}.
std::string intrinsicsJson(const Intrinsics& intrinsics);

struct SessionInfo {
  int64_t id = 0;
  std::string name;
  std::string intrinsics_json;  // as the client sent them
  std::string params_json;      // effective parameters of the session
  std::string started_at, ended_at;  // ISO-8601 UTC; ended_at empty while open
  SessionState state = SessionState::kOpen;
  int64_t frames = 0;
};

// A blob (or a row) that could not be read back.
struct Damage {
  std::string table;
  int64_t row = 0;       // rowid / model id
  std::string column;
  std::string problem;
};

struct CheckReport {
  std::vector<std::string> sqlite_findings;  // PRAGMA integrity_check lines other than "ok"
  std::vector<Damage> damaged;              // blobs failing their checks
  size_t blobs_checked = 0;
  bool ok() const { return sqlite_findings.empty() && damaged.empty(); }
};

struct TableStats {
  std::string table;
  int64_t rows = 0;
  int64_t blob_bytes = 0;  // sum of blob lengths in the table
};

struct StoreStats {
  int schema_version = 0;
  int64_t file_bytes = 0;  // page_count · page_size (WAL not included)
  int64_t active_models = 0, removed_models = 0, merged_models = 0;
  std::vector<TableStats> tables;
};

// One model's row without its blobs, with its observations: what listings need (ListObjects,
// GetObject), cheap to read for many models.
struct ModelSummary {
  struct Pose {
    std::string session;
    uint32_t label = 0;           // GSM label of the observing raw segment
    int64_t raw_segment_id = 0;   // raw_segments row (0 when the segment row is gone)
    Transform T_world_object = Transform::Identity();
    std::vector<uint32_t> parts;  // the raw segment's GSM labels (its object's parts), sorted
  };
  int64_t id = 0;
  std::string state;             // "active" or "merged" (removed models are never listed)
  int64_t merged_into = 0;       // state "merged": the model that absorbed it
  bool planar = false;
  bool structure = false;        // room structure (core/model/structure.h): never matched
  int64_t num_points = 0, num_keypoints = 0;
  double voxel_size = 0.0;
  Eigen::Vector3d bbox_min = Eigen::Vector3d::Zero(), bbox_max = Eigen::Vector3d::Zero();  // model frame
  std::vector<Pose> observations;  // insertion order
  int64_t merges = 0;              // merge records with this model as target
};

// Which models modelSummaries() returns: ids above after_id, ascending, at most `limit`.
struct ModelQuery {
  int64_t after_id = 0;
  size_t limit = 100;
  std::string session;          // only models observed in this session; empty = all
  bool include_merged = false;  // also models in state "merged"
  bool include_structure = true;  // false: only models not flagged room structure
};

struct EncodedModel;  // a model's columns as blobs (sqlite_store.cpp)

class SqliteStore : public database::ModelStore {
 public:
  static StatusOr<std::unique_ptr<SqliteStore>> open(const std::string& path,
                                                     const SqliteStoreOptions& options = {});
  // With another migration list (tests of the migration machinery).
  static StatusOr<std::unique_ptr<SqliteStore>> open(const std::string& path,
                                                     const SqliteStoreOptions& options,
                                                     const std::vector<Migration>& migrations);
  ~SqliteStore() override;

  const std::string& path() const { return path_; }
  const SchemaState& schema() const { return schema_; }

  // ModelStore.
  Status putRawSegment(const database::RawSegmentRecord& segment) override;
  StatusOr<std::shared_ptr<const database::RawSegmentRecord>> rawSegment(
      const database::SegmentKey& key) const override;
  StatusOr<int64_t> addModel(model::ObjectModel model) override;
  Status replaceModel(model::ObjectModel model,
                      const std::optional<database::MergeRecord>& merge) override;
  Status absorbModel(model::ObjectModel target, const database::MergeRecord& merge,
                     int64_t absorbed) override;
  Status removeModel(int64_t id) override;
  StatusOr<std::shared_ptr<const model::ObjectModel>> model(int64_t id) const override;
  StatusOr<std::vector<int64_t>> modelIds() const override;
  StatusOr<database::MatchEntries> matchEntries() const override;
  StatusOr<std::vector<database::MergeRecord>> mergeRecords() const override;
  // The merge records whose target is model `target`, oldest first.
  StatusOr<std::vector<database::MergeRecord>> mergeRecordsInto(int64_t target) const;
  Status putScene(const std::string& session, std::shared_ptr<const tsdf::TsdfLayer> scene,
                  std::shared_ptr<const gsm::LabelBlocks> labels = nullptr) override;
  StatusOr<std::shared_ptr<const tsdf::TsdfLayer>> scene(
      const std::string& session) const override;
  StatusOr<std::shared_ptr<const gsm::LabelBlocks>> sceneLabels(
      const std::string& session) const override;

  // The live map of an open session, saved now and then so that a crash loses only what came
  // after (replacing the earlier save). It is not the session's scene map: scene() does not see
  // it, and finishSession(kEnded) deletes it.
  Status putSavedMap(const std::string& session, int64_t frames, const tsdf::TsdfLayer& map,
                     const gsm::LabelBlocks& labels);
  StatusOr<SavedMap> savedMap(const std::string& session) const;
  // The frame count of the session's saved map without reading it; −1 when none is saved.
  StatusOr<int64_t> savedMapFrames(const std::string& session) const;
  Status dropSavedMap(const std::string& session);

  // Model rows without blobs (see ModelQuery), one snapshot.
  StatusOr<std::vector<ModelSummary>> modelSummaries(const ModelQuery& query) const;
  // The id of a stored raw segment (NOT_FOUND when none has that key).
  StatusOr<int64_t> rawSegmentId(const database::SegmentKey& key) const;

  // Sessions. beginSession creates the session (ALREADY_EXISTS when the name is taken);
  // a session row is also created implicitly, state open, by the first data stored for it.
  StatusOr<SessionInfo> beginSession(const SessionInfo& info);
  Status finishSession(const std::string& name, SessionState state, int64_t frames);
  StatusOr<std::vector<SessionInfo>> sessions() const;

  // SQLite's integrity_check plus every blob's checks.
  StatusOr<CheckReport> check() const;
  StatusOr<StoreStats> stats() const;
  // Copies the WAL into the database and truncates it (clean shutdown).
  Status checkpoint();
  // An online backup: a consistent copy of the database (one read snapshot, through SQLite's
  // backup API) in a new file at `path`, while writers carry on (their commits do not wait; the
  // WAL grows until the copy is done). The copy is written to a temporary file next to `path`,
  // synced, and linked to `path`, so `path` is whole or absent and never replaced. An existing
  // `path` (or a -wal, -shm or -journal of it) is ALREADY_EXISTS and left alone.
  StatusOr<BackupReport> backupTo(const std::string& path) const;

 private:
  class ReaderLease;
  SqliteStore(std::string path, SqliteStoreOptions options);
  StatusOr<ReaderLease> reader() const;
  Status requireWriter() const;
  StatusOr<std::vector<database::MergeRecord>> readMergeRecords(
      std::optional<int64_t> target) const;
  StatusOr<int64_t> sessionIdForWrite(const std::string& name);
  Status writeObservations(int64_t model_id, const EncodedModel& model, bool replace);
  Status rewriteModel(const EncodedModel& e, int64_t id, const database::MergeRecord* merge);
  Status retireModel(int64_t id, int64_t merged_into);
  // A map (TSDF blocks, optional main labels) into `tables`, replacing the session's earlier one;
  // `frames` is kept where the tables have the column (saved maps).
  Status writeMap(const MapTables& tables, const std::string& session,
                  const tsdf::TsdfLayer& scene, const gsm::LabelBlocks* labels, int64_t frames);
  // A map from `tables` (null when the session has none); `frames` gets its frame count.
  StatusOr<std::shared_ptr<const tsdf::TsdfLayer>> readMapTsdf(const Connection& connection,
                                                               const MapTables& tables,
                                                               const std::string& session,
                                                               int64_t* frames) const;
  // Deletes the session's saved map (writer, inside the caller's transaction).
  Status deleteSavedMap(const std::string& session);
  StatusOr<std::shared_ptr<const gsm::LabelBlocks>> readMapLabels(const Connection& connection,
                                                                  const MapTables& tables,
                                                                  const std::string& session) const;

  std::string path_;
  SqliteStoreOptions options_;
  // This store's hold on its file (and the writer lock, for a writable store). Declared before
  // the connections, so that it is released after they are closed.
  std::optional<FileRegistration> registration_;
  SchemaState schema_;
  mutable std::mutex write_mutex_;  // one writer at a time
  std::optional<Connection> writer_;
  mutable std::mutex reader_mutex_;
  mutable std::vector<Connection> idle_readers_;
  // Decoded scene maps (large; read by every model-to-scene check), replaced on putScene.
  mutable std::mutex scene_mutex_;
  // Most recently used first; at most options_.max_cached_scenes entries each.
  mutable std::list<std::pair<std::string, std::shared_ptr<const tsdf::TsdfLayer>>> scene_cache_;
  mutable std::list<std::pair<std::string, std::shared_ptr<const gsm::LabelBlocks>>> label_cache_;
};

}  // namespace objdb::storage
