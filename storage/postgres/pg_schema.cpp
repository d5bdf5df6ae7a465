#include "storage/postgres/pg_schema.h"

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "core/common/logging.h"

namespace objdb::storage::pg {
namespace {

// PostgreSQL's words for the shared tables (storage/shared_schema.h): ids come from identity
// columns, never reused; block and observation rows have an id of their own, for messages.
constexpr SqlDialect kDialect{"BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY",
                              "BIGINT",
                              "DOUBLE PRECISION",
                              "BYTEA",
                              "BOOLEAN",
                              "FALSE",
                              "  id BIGINT GENERATED ALWAYS AS IDENTITY UNIQUE,\n"};

// Version 1: the data model of the SQLite store's schema 5 (storage/sqlite/schema.cpp), in
// PostgreSQL's types, and the table that names the application and the schema version.
std::string schemaV1() {
  return absl::StrCat(R"sql(
CREATE TABLE objdb_meta (
  key TEXT PRIMARY KEY,
  value TEXT NOT NULL
);
)sql",
                      sessionsTable(kDialect), mapTables(kDialect, kSceneTables),
                      mapTables(kDialect, kSavedTables),
                      segmentAndModelTables(kDialect, /*added_up_to=*/5),
                      "INSERT INTO objdb_meta(key, value) VALUES ('application', 'objdb'), "
                      "('schema_version', '0');\n");
}

// Version 2: several servers on one database. Session leases (the server streaming or ending a
// session; expiry by the database's clock, so the servers' clocks do not matter), and a change
// sequence on models: every write of a model row takes the next number, so that a server
// catches up on the models the others changed (ModelStore::modelChangesSince).
constexpr const char* kSchemaV2 = R"sql(
CREATE TABLE session_leases (
  session TEXT PRIMARY KEY,
  owner TEXT NOT NULL,
  expires_at TIMESTAMPTZ NOT NULL
);
CREATE SEQUENCE model_changes;
ALTER TABLE models ADD COLUMN change_seq BIGINT NOT NULL DEFAULT 0;
CREATE INDEX models_by_change ON models(change_seq);
)sql";

// Serialises schema preparation across servers (pg_advisory_xact_lock key: "OBJD").
constexpr int64_t kSchemaLock = 0x4F424A44;

// The schema version recorded in the database: 0 for an empty database; FAILED_PRECONDITION for
// one with tables that are not objdb's.
StatusOr<int> recordedVersion(const Connection& c, const std::string& describe) {
  OBJDB_ASSIGN_OR_RETURN(Result meta,
                         c.exec("SELECT to_regclass('objdb_meta') IS NOT NULL", "reading the schema"));
  if (!meta.boolean(0, 0)) {
    OBJDB_ASSIGN_OR_RETURN(
        Result tables,
        c.exec("SELECT COUNT(*) FROM information_schema.tables WHERE table_schema = "
               "current_schema()",
               "reading the schema"));
    if (tables.integer(0, 0) != 0) {
      return absl::FailedPreconditionError(absl::StrFormat(
          "%s holds %d tables that are not objdb's (no objdb_meta table); refusing to touch it; "
          "give objdb a database of its own",
          describe, tables.integer(0, 0)));
    }
    return 0;
  }
  OBJDB_ASSIGN_OR_RETURN(Result rows, c.exec("SELECT key, value FROM objdb_meta WHERE key IN "
                                             "('application', 'schema_version')",
                                             "reading objdb_meta"));
  std::string application;
  int version = -1;
  for (int r = 0; r < rows.rows(); ++r) {
    if (rows.text(r, 0) == "application") application = rows.text(r, 1);
    if (rows.text(r, 0) == "schema_version" && !absl::SimpleAtoi(rows.text(r, 1), &version)) {
      version = -1;
    }
  }
  if (application != "objdb" || version < 0) {
    return absl::FailedPreconditionError(absl::StrFormat(
        "%s has an objdb_meta table of another application (application '%s'); refusing to "
        "touch it",
        describe, application));
  }
  return version;
}

}  // namespace

const std::vector<Migration>& schemaMigrations() {
  static const std::vector<Migration> migrations = {
      {1, "sessions, maps, raw segments, models, observations, merge records", schemaV1()},
      {2, "several servers: session leases, the models' change sequence", kSchemaV2},
      // SQLite's schema 6.
      {3, "sessions that outlive their server: sessions.client, sessions.counters",
       addedColumns(kDialect, 6)},
      // SQLite's schema 7.
      {4, "two-stage retrieval: models.global_descriptor", addedColumns(kDialect, 7)},
  };
  return migrations;
}

StatusOr<SchemaState> prepareSchema(const Connection& c, const std::string& describe,
                                    const std::vector<Migration>& migrations) {
  if (migrations.empty()) return absl::InvalidArgumentError("no schema migrations given");
  const int latest = migrations.back().version;
  SchemaState state;
  bool first = true;
  while (true) {
    OBJDB_RETURN_IF_ERROR(c.exec("BEGIN", "preparing the schema").status());
    auto step = [&]() -> StatusOr<bool> {  // true: at the latest version
      Params lock;
      lock.add(kSchemaLock);
      OBJDB_RETURN_IF_ERROR(
          c.exec("SELECT pg_advisory_xact_lock($1)", lock, "locking the schema").status());
      OBJDB_ASSIGN_OR_RETURN(const int version, recordedVersion(c, describe));
      if (first) {
        state.version_before = version;
        state.created = version == 0;
        first = false;
      }
      if (version > latest) {
        return absl::FailedPreconditionError(absl::StrFormat(
            "%s has objdb schema version %d, newer than this build reads (up to %d); use a "
            "newer objdb",
            describe, version, latest));
      }
      if (version == latest) return true;
      const Migration* next = nullptr;
      for (const auto& m : migrations) {
        if (m.version > version) {
          next = &m;
          break;
        }
      }
      const std::string context = absl::StrFormat("%s: migrating to schema %d (%s)", describe,
                                                  next->version, next->description);
      OBJDB_RETURN_IF_ERROR(c.script(next->sql, context));
      Params v;
      v.text(std::to_string(next->version));
      OBJDB_RETURN_IF_ERROR(
          c.exec("UPDATE objdb_meta SET value = $1 WHERE key = 'schema_version'", v, context)
              .status());
      if (!state.created) {
        logger("storage")->info("{}: migrated to schema {} ({})", describe, next->version,
                                next->description);
      }
      return next->version == latest;
    };
    auto done = step();
    if (!done.ok()) {
      (void)c.exec("ROLLBACK", "preparing the schema");
      return done.status();
    }
    OBJDB_RETURN_IF_ERROR(c.exec("COMMIT", "preparing the schema").status());
    if (*done) break;
  }
  state.version_after = latest;
  return state;
}

}  // namespace objdb::storage::pg
