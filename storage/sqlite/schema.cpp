#include "storage/sqlite/schema.h"

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "core/common/logging.h"

namespace objdb::storage {
namespace {

// SQLite's words for the shared tables (storage/shared_schema.h): ids are AUTOINCREMENT so that
// no id is ever reused; block and observation rows have their rowid.
constexpr SqlDialect kDialect{
    "INTEGER PRIMARY KEY AUTOINCREMENT", "INTEGER", "REAL", "BLOB", "INTEGER", "0", ""};

}  // namespace

// Each step's SQL is what files of that version hold in sqlite_schema: it must not change.
const std::vector<Migration>& schemaMigrations() {
  static const std::vector<Migration> migrations = {
      {1, "sessions, scene maps, raw segments, models, observations, merge records",
       absl::StrCat("\n", sessionsTable(kDialect), mapTables(kDialect, kSceneTables),
                    segmentAndModelTables(kDialect, /*added_up_to=*/0))},
      // Saved live maps of open sessions (a crash loses only the frames after the last save).
      {2, "saved live maps of open sessions",
       absl::StrCat("\n", mapTables(kDialect, kSavedTables))},
      {3, "room structure: models.structure, raw_segments.observation_depth_m",
       absl::StrCat("\n", addedColumns(kDialect, 3))},
      {4, "whole objects: raw_segments.parts", absl::StrCat("\n", addedColumns(kDialect, 4))},
      {5, "parts with geometry: raw_segments.voxel_parts",
       absl::StrCat("\n", addedColumns(kDialect, 5))},
      {6, "sessions that outlive their server: sessions.client, sessions.counters",
       absl::StrCat("\n", addedColumns(kDialect, 6))},
      {7, "two-stage retrieval: models.global_descriptor",
       absl::StrCat("\n", addedColumns(kDialect, 7))},
  };
  return migrations;
}

int currentSchemaVersion() { return schemaMigrations().back().version; }

StatusOr<SchemaState> prepareSchema(const Connection& connection, const std::string& path,
                                    const std::vector<Migration>& migrations, bool read_only) {
  if (migrations.empty()) return absl::InvalidArgumentError("no schema migrations given");
  const int latest = migrations.back().version;
  // The first read of the file: SQLite reports a non-database here (SQLITE_NOTADB).
  auto tables = connection.queryInt("SELECT COUNT(*) FROM sqlite_schema",
                                    absl::StrFormat("reading %s", path));
  if (!tables.ok()) return tables.status();
  OBJDB_ASSIGN_OR_RETURN(const int64_t application_id,
                         connection.queryInt("PRAGMA application_id", "reading application_id"));
  OBJDB_ASSIGN_OR_RETURN(const int64_t user_version,
                         connection.queryInt("PRAGMA user_version", "reading user_version"));
  SchemaState state;
  state.version_before = int(user_version);
  const bool empty = *tables == 0 && application_id == 0 && user_version == 0;
  if (!empty && application_id != kApplicationId) {
    return absl::FailedPreconditionError(absl::StrFormat(
        "%s is an SQLite database of another application (application_id 0x%08x, objdb's is "
        "0x%08x); refusing to touch it",
        path, uint32_t(application_id), uint32_t(kApplicationId)));
  }
  if (user_version > latest) {
    return absl::FailedPreconditionError(absl::StrFormat(
        "%s has schema version %d, newer than this build reads (up to %d); use a newer objdb",
        path, user_version, latest));
  }
  if (user_version == latest) {
    state.version_after = latest;
    return state;
  }
  if (read_only) {
    return absl::FailedPreconditionError(absl::StrFormat(
        "%s has schema version %d and needs migrating to %d; open it writable once", path,
        user_version, latest));
  }
  if (empty) {
    // WAL is persistent in the file (wal.html §3.3); set once, before the first table.
    auto mode = Statement::prepare(connection, "PRAGMA journal_mode=WAL");
    if (!mode.ok()) return mode.status();
    OBJDB_ASSIGN_OR_RETURN(const bool row, mode->step());
    if (!row || mode->columnText(0) != "wal") {
      return absl::UnavailableError(absl::StrFormat(
          "%s: could not switch to WAL journal mode (got '%s')", path,
          row ? mode->columnText(0) : std::string("nothing")));
    }
    state.created = true;
  }
  for (const auto& m : migrations) {
    if (m.version <= user_version) continue;
    OBJDB_ASSIGN_OR_RETURN(Transaction txn, Transaction::begin(connection, Transaction::Kind::kWrite));
    const std::string context =
        absl::StrFormat("%s: migrating to schema %d (%s)", path, m.version, m.description);
    OBJDB_RETURN_IF_ERROR(connection.exec(m.sql, context));
    OBJDB_RETURN_IF_ERROR(connection.exec(
        absl::StrFormat("PRAGMA application_id=%d; PRAGMA user_version=%d;", kApplicationId,
                        m.version),
        context));
    OBJDB_RETURN_IF_ERROR(txn.commit());
    if (!state.created) logger("storage")->info("{}: migrated to schema {} ({})", path, m.version,
                                                m.description);
  }
  state.version_after = latest;
  return state;
}

}  // namespace objdb::storage
