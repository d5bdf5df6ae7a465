// The networked backend of storage::Store (storage/store.h; docs/storage.md): one PostgreSQL
// database reached through libpq, shared by several objdb servers. A pool of connections; every
// mutation one READ COMMITTED transaction that locks the rows it updates before their dependants
// (a model row before its observations, a map row before its blocks), retried (a bounded,
// counted number of times) when PostgreSQL reports a deadlock or serialization failure; every read of several rows one
// REPEATABLE READ snapshot. Binary data in the same checksummed blobs as the SQLite backend
// (storage/blob_codec.h), as bytea. Statements take parameters only. The implementation is split
// like the SQLite one: postgres_store.cpp (opening, raw segments, merge records),
// postgres_models.cpp, postgres_maps.cpp, postgres_sessions.cpp, postgres_maintenance.cpp;
// pg_schema.h holds the schema and its migrations, pg_util.h the thin libpq layer.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "storage/blob_codec.h"
#include "storage/store.h"

namespace objdb::storage {

namespace pg {
class ConnectionPool;  // pg_util.h
struct Migration;      // pg_schema.h
}  // namespace pg

// Whether `target` names a PostgreSQL database (a libpq URI: postgresql://… or postgres://…)
// rather than an SQLite file.
bool isPostgresTarget(const std::string& target);

// `uri` with any password replaced by "***" (for logs and messages).
std::string redactPostgresUri(const std::string& uri);

struct PostgresStoreOptions {
  int pool_size = 4;                 // connections kept open (more are opened on demand)
  int connect_timeout_s = 10;        // libpq connect_timeout, when the URI does not set one
  int max_transaction_retries = 8;   // on serialization failure / deadlock, then UNAVAILABLE
  // Decoded scene maps kept in memory, as SqliteStoreOptions::max_cached_scenes.
  int max_cached_scenes = 8;
  BlobOptions blobs;                 // compression of new blobs
  Status validate() const;
};

class PostgresStore : public Store {
 public:
  // Connects to the database of `uri` (credentials from the URI, PGPASSFILE/~/.pgpass or
  // PGPASSWORD, as libpq reads them; TLS as the URI's sslmode asks) and brings its schema to the
  // current version. Errors: UNAVAILABLE when the server cannot be reached, UNAUTHENTICATED for
  // refused credentials, FAILED_PRECONDITION for a database of another application or of a newer
  // objdb schema (nothing written), INVALID_ARGUMENT for a malformed URI.
  static StatusOr<std::unique_ptr<PostgresStore>> open(const std::string& uri,
                                                       const PostgresStoreOptions& options = {});
  ~PostgresStore() override;

  int schemaVersion() const { return schema_version_; }

  // The implementation's state (postgres_internal.h), shared by the files of storage/postgres/.
  class Impl;
  // Transactions retried after a serialization failure or deadlock, since open.
  int64_t transactionRetries() const;

  // Store.
  std::string describe() const override;
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
  // Several servers on one database (postgres_fleet.cpp): leases in table session_leases, timed
  // by the database's clock; the writer lock is a PostgreSQL advisory lock on a connection of
  // its own (released by the database if that connection or this process dies).
  StatusOr<std::string> acquireLease(const std::string& session, const std::string& owner,
                                     std::chrono::milliseconds ttl) override;
  StatusOr<std::vector<std::string>> renewLeases(const std::string& owner,
                                                 std::chrono::milliseconds ttl) override;
  Status releaseLease(const std::string& session, const std::string& owner) override;
  StatusOr<std::unique_ptr<database::WriterLock>> lockWriter() override;
  StatusOr<int64_t> modelChangeSeq() const override;
  StatusOr<database::ModelChanges> modelChangesSince(int64_t seq) const override;
  // Foreign keys and constraints are PostgreSQL's to enforce: the check decodes every blob, and
  // reports observations linked to a raw segment row of another session or label.
  StatusOr<CheckReport> check() const override;
  StatusOr<StoreStats> stats() const override;
  // A commit is durable when it returns (synchronous_commit): nothing to do.
  Status checkpoint() override;
  // A pg_dump archive (custom format, one snapshot while writers go on) at `path`, written
  // under a temporary name and linked into place; restore it with pg_restore into an empty
  // database. pg_dump (postgresql-client) must be on PATH: FAILED_PRECONDITION otherwise.
  // BackupReport::pages is 0, bytes the archive's size. Continuous archiving or pg_basebackup
  // remain the tools for point-in-time recovery.
  StatusOr<BackupReport> backupTo(const std::string& path) const override;

 private:
  PostgresStore(std::string uri, PostgresStoreOptions options);
  std::string uri_;
  PostgresStoreOptions options_;
  int schema_version_ = 0;
  std::unique_ptr<Impl> impl_;
};

}  // namespace objdb::storage
