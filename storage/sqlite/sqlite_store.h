// The embedded backend of storage::Store (storage/store.h; docs/storage.md): one SQLite
// file in WAL mode. One writer connection (every mutation one BEGIN IMMEDIATE transaction), a pool
// of reader connections (every read one snapshot), binary data in checksummed, versioned,
// compressed blobs (storage/blob_codec.h). A damaged blob fails only the row that holds it, with
// an error naming table, row and column. The implementation is split by concern: sqlite_store.cpp
// (opening, raw segments, merge records), sqlite_models.cpp (object models and listings),
// sqlite_maps.cpp (scene and saved maps, the scene cache), sqlite_sessions.cpp,
// sqlite_maintenance.cpp (check, stats, checkpoint, backup), file_registration.cpp (one writer per
// file); schema.h holds the schema and its migrations, sqlite_util.h the thin SQLite C API layer.
#pragma once

#include <chrono>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "core/database/model_store.h"
#include "storage/blob_codec.h"
#include "storage/row_codec.h"
#include "storage/sqlite/file_registration.h"
#include "storage/sqlite/schema.h"
#include "storage/sqlite/sqlite_util.h"
#include "storage/store.h"

namespace objdb::storage {

namespace internal {
struct MapTables;  // sqlite_store_internal.h
}  // namespace internal

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

class SqliteStore : public Store {
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

  // Store (storage/store.h documents these).
  std::string describe() const override { return path_; }
  int64_t diskBytes() const override;

  // database::ModelStore.
  Status putRawSegment(const database::RawSegmentRecord& segment) override;
  StatusOr<std::shared_ptr<const database::RawSegmentRecord>> rawSegment(
      const database::SegmentKey& key) const override;
  StatusOr<int64_t> addModel(model::ObjectModel model) override;
  Status replaceModel(model::ObjectModel model,
                      const std::optional<database::MergeRecord>& merge) override;
  Status absorbModel(model::ObjectModel target, const database::MergeRecord& merge,
                     int64_t absorbed) override;
  Status removeModel(int64_t id) override;
  Status setSuccessor(int64_t removed, int64_t successor) override;
  StatusOr<std::shared_ptr<const model::ObjectModel>> model(int64_t id) const override;
  StatusOr<std::vector<int64_t>> modelIds() const override;
  StatusOr<database::MatchEntries> matchEntries() const override;
  StatusOr<std::vector<database::MergeRecord>> mergeRecords() const override;
  StatusOr<std::vector<database::MergeRecord>> mergeRecordsInto(int64_t target) const override;
  Status putScene(const std::string& session, std::shared_ptr<const tsdf::TsdfLayer> scene,
                  std::shared_ptr<const gsm::LabelBlocks> labels = nullptr) override;
  StatusOr<std::shared_ptr<const tsdf::TsdfLayer>> scene(
      const std::string& session) const override;
  StatusOr<std::shared_ptr<const gsm::LabelBlocks>> sceneLabels(
      const std::string& session) const override;

  // Store.
  Status putSavedMap(const std::string& session, int64_t frames, const tsdf::TsdfLayer& map,
                     const gsm::LabelBlocks& labels) override;
  StatusOr<SavedMap> savedMap(const std::string& session) const override;
  StatusOr<int64_t> savedMapFrames(const std::string& session) const override;
  Status dropSavedMap(const std::string& session) override;
  StatusOr<std::vector<ModelSummary>> modelSummaries(const ModelQuery& query) const override;
  StatusOr<ModelFate> modelFate(int64_t id) const override;
  StatusOr<int64_t> rawSegmentId(const database::SegmentKey& key) const override;
  StatusOr<SessionInfo> beginSession(const SessionInfo& info) override;
  Status finishSession(const std::string& name, SessionState state, int64_t frames) override;
  StatusOr<std::vector<SessionInfo>> sessions() const override;
  // Leases in memory: one process owns the file (FileRegistration), so one server holds them all
  // and a lease never outlives it.
  StatusOr<std::string> acquireLease(const std::string& session, const std::string& owner,
                                     std::chrono::milliseconds ttl) override;
  StatusOr<std::vector<std::string>> renewLeases(const std::string& owner,
                                                 std::chrono::milliseconds ttl) override;
  Status releaseLease(const std::string& session, const std::string& owner) override;
  // SQLite's integrity_check and foreign_key_check plus every blob's checks.
  StatusOr<CheckReport> check() const override;
  StatusOr<StoreStats> stats() const override;
  // Copies the WAL into the database and truncates it (clean shutdown).
  Status checkpoint() override;
  // An online backup: a consistent copy of the database (one read snapshot, through SQLite's
  // backup API) in a new file at `path`, while writers carry on (their commits do not wait; the
  // WAL grows until the copy is done). The copy is written to a temporary file next to `path`,
  // synced, and linked to `path`, so `path` is whole or absent and never replaced. An existing
  // `path` (or a -wal, -shm or -journal of it) is ALREADY_EXISTS and left alone.
  StatusOr<BackupReport> backupTo(const std::string& path) const override;

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
  Status writeMap(const internal::MapTables& tables, const std::string& session,
                  const tsdf::TsdfLayer& scene, const gsm::LabelBlocks* labels, int64_t frames);
  // A map from `tables` (null when the session has none); `frames` gets its frame count.
  StatusOr<std::shared_ptr<const tsdf::TsdfLayer>> readMapTsdf(
      const Connection& connection, const internal::MapTables& tables, const std::string& session,
      int64_t* frames) const;
  // Deletes the session's saved map (writer, inside the caller's transaction).
  Status deleteSavedMap(const std::string& session);
  StatusOr<std::shared_ptr<const gsm::LabelBlocks>> readMapLabels(
      const Connection& connection, const internal::MapTables& tables,
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
  // Decoded scene maps (large; read by every model-to-scene check), replaced on putScene; at most
  // options_.max_cached_scenes sessions.
  mutable SceneCache scene_cache_;
  struct Lease {
    std::string owner;
    std::chrono::steady_clock::time_point expires;
  };
  std::mutex lease_mutex_;
  std::map<std::string, Lease> leases_;  // by session name
};

}  // namespace objdb::storage
