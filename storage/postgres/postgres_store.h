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
}  // namespace pg

// Whether `target` names a PostgreSQL database (a libpq URI: postgresql://… or postgres://…)
// rather than an SQLite file.
bool isPostgresTarget(const std::string& target);

// `uri` with any password replaced by "***" (for logs and messages).
std::string redactPostgresUri(const std::string& uri);

struct PostgresStoreOptions : BackendOptions {
  int pool_size = 4;                 // connections kept open (more are opened on demand)
  int connect_timeout_s = 10;        // libpq connect_timeout, when the URI does not set one
  int max_transaction_retries = 8;   // on serialization failure / deadlock, then UNAVAILABLE
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

  // The overrides of Store and database::ModelStore. Here:
  // - Leases (postgres_fleet.cpp): in table session_leases, timed by the database's clock.
  // - check(): foreign keys and constraints are PostgreSQL's to enforce; the check decodes every
  //   blob, and reports observations linked to a raw segment row of another session or label.
  // - checkpoint(): a commit is durable when it returns (synchronous_commit): nothing to do.
  // - backupTo(): a pg_dump archive (custom format, one snapshot while writers go on) at `path`,
  //   written under a temporary name and linked into place; restore it with pg_restore into an
  //   empty database. pg_dump (postgresql-client) must be on PATH: FAILED_PRECONDITION
  //   otherwise. BackupReport::pages is 0, bytes the archive's size. Continuous archiving or
  //   pg_basebackup remain the tools for point-in-time recovery.
#include "storage/store_overrides.inc"
  bool sharedByServers() const override { return true; }
  // Writes the blocks that differ from the base, in one transaction (postgres_maps.cpp).
  Status updateSavedMap(const std::string& session, int64_t frames, const tsdf::TsdfLayer& map,
                        const gsm::LabelBlocks& labels, const tsdf::TsdfLayer& base_map,
                        const gsm::LabelBlocks& base_labels) override;
  // Several servers on one database (postgres_fleet.cpp): the writer lock is a PostgreSQL
  // advisory lock on a connection of its own (released by the database if that connection or
  // this process dies); the model changes are read from the models' change sequence.
  StatusOr<std::unique_ptr<database::WriterLock>> lockWriter() override;
  StatusOr<int64_t> modelChangeSeq() const override;
  StatusOr<database::ModelChanges> modelChangesSince(int64_t seq) const override;

 private:
  PostgresStore(std::string uri, PostgresStoreOptions options);
  std::string uri_;
  PostgresStoreOptions options_;
  int schema_version_ = 0;
  std::unique_ptr<Impl> impl_;
};

}  // namespace objdb::storage
