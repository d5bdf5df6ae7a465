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

struct SqliteStoreOptions : BackendOptions {
  bool create_if_missing = true;  // create an empty database when the file does not exist
  bool read_only = false;         // no writer connection; mutations fail with FAILED_PRECONDITION
  std::string synchronous = "FULL";  // FULL: commits survive power loss; NORMAL: survive
                                     // process crashes, may lose the last commits on power loss
  int busy_timeout_ms = 5000;     // how long a connection waits for a lock before UNAVAILABLE
  int64_t journal_size_limit_bytes = 64ll << 20;  // WAL file is truncated to this after checkpoints
  bool quick_check_on_open = true;  // PRAGMA quick_check before first use; corrupt → DATA_LOSS
  int max_readers = 8;              // reader connections kept open (more are opened on demand)
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

  // The overrides of Store and database::ModelStore. Here:
  // - describe(): the file's path.
  // - Leases in memory: one process owns the file (FileRegistration), so one server holds them
  //   all and a lease never outlives it.
  // - check(): SQLite's integrity_check and foreign_key_check plus every blob's checks.
  // - checkpoint(): copies the WAL into the database and truncates it (clean shutdown).
  // - backupTo(): an online backup: a consistent copy of the database (one read snapshot,
  //   through SQLite's backup API) in a new file at `path`, while writers carry on (their commits
  //   do not wait; the WAL grows until the copy is done). The copy is written to a temporary file
  //   next to `path`, synced, and linked to `path`, so `path` is whole or absent and never
  //   replaced. An existing `path` (or a -wal, -shm or -journal of it) is ALREADY_EXISTS and left
  //   alone.
#include "storage/store_overrides.inc"

 private:
  class ReaderLease;
  SqliteStore(std::string path, SqliteStoreOptions options);
  StatusOr<ReaderLease> reader() const;
  // The writer, held (write_mutex_ locked); FAILED_PRECONDITION for a read-only store.
  StatusOr<std::unique_lock<std::mutex>> holdWriter() const;
  StatusOr<std::vector<database::MergeRecord>> readMergeRecords(
      std::optional<int64_t> target) const;
  StatusOr<int64_t> sessionIdForWrite(const std::string& name);
  Status writeObservations(int64_t model_id, const EncodedModel& model, bool replace);
  Status rewriteModel(const EncodedModel& e, int64_t id, const database::MergeRecord* merge);
  Status retireModel(int64_t id, int64_t merged_into);
  // A map (TSDF blocks, optional main labels) into `tables`, replacing the session's earlier one;
  // `frames` is kept where the tables have the column (saved maps).
  Status writeMap(const MapTables& tables, const std::string& session, const tsdf::TsdfLayer& scene,
                  const gsm::LabelBlocks* labels, int64_t frames);
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
  // Decoded scene maps (large; read by every model-to-scene check), replaced on putScene; at most
  // options_.max_cached_scenes sessions.
  mutable SceneCache scene_cache_;
  struct Lease {
    std::string owner;
    std::chrono::steady_clock::time_point expires;
  };
  mutable std::mutex lease_mutex_;
  std::map<std::string, Lease> leases_;  // by session name
};

}  // namespace objdb::storage
