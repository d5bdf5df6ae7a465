#include "storage/sqlite/schema.h"

#include "absl/strings/str_format.h"
#include "core/common/logging.h"

namespace objdb::storage {
namespace {

// Version 1: the first data model. Times are ISO-8601 UTC text; binary columns are
// blobs of storage/blob_codec.h. Ids are AUTOINCREMENT so that no id is ever reused.
constexpr const char* kSchemaV1 = R"sql(
CREATE TABLE sessions (
  id INTEGER PRIMARY KEY AUTOINCREMENT,
  name TEXT NOT NULL UNIQUE,
  intrinsics TEXT NOT NULL DEFAULT '',
  params TEXT NOT NULL DEFAULT '',
  started_at TEXT NOT NULL,
  ended_at TEXT,
  state TEXT NOT NULL CHECK (state IN ('open', 'ended', 'interrupted')),
  frames INTEGER NOT NULL DEFAULT 0
);
CREATE TABLE scene_maps (
  session_id INTEGER PRIMARY KEY REFERENCES sessions(id),
  voxel_size REAL NOT NULL,
  voxels_per_side INTEGER NOT NULL,
  blocks INTEGER NOT NULL,
  updated_at TEXT NOT NULL
);
CREATE TABLE scene_blocks (
  session_id INTEGER NOT NULL REFERENCES scene_maps(session_id) ON DELETE CASCADE,
  bx INTEGER NOT NULL,
  by INTEGER NOT NULL,
  bz INTEGER NOT NULL,
  tsdf BLOB NOT NULL,
  PRIMARY KEY (session_id, bx, by, bz)
);
CREATE TABLE scene_label_blocks (
  session_id INTEGER NOT NULL REFERENCES scene_maps(session_id) ON DELETE CASCADE,
  bx INTEGER NOT NULL,
  by INTEGER NOT NULL,
  bz INTEGER NOT NULL,
  labels BLOB NOT NULL,
  PRIMARY KEY (session_id, bx, by, bz)
);
CREATE TABLE raw_segments (
  id INTEGER PRIMARY KEY AUTOINCREMENT,
  session_id INTEGER NOT NULL REFERENCES sessions(id),
  label INTEGER NOT NULL,
  pose BLOB NOT NULL,
  grid BLOB NOT NULL,
  voxels BLOB NOT NULL,
  extraction_frame INTEGER NOT NULL,
  extracted_at TEXT NOT NULL,
  UNIQUE (session_id, label)
);
CREATE TABLE models (
  id INTEGER PRIMARY KEY AUTOINCREMENT,
  state TEXT NOT NULL CHECK (state IN ('active', 'merged', 'removed')),
  merged_into INTEGER REFERENCES models(id),
  planar INTEGER NOT NULL,
  plane_inlier_ratio REAL NOT NULL,
  num_points INTEGER NOT NULL,
  num_keypoints INTEGER NOT NULL,
  voxel_size REAL,
  bbox_min_x REAL, bbox_min_y REAL, bbox_min_z REAL,
  bbox_max_x REAL, bbox_max_y REAL, bbox_max_z REAL,
  grid BLOB,
  surface_voxels BLOB,
  cloud BLOB,
  keypoints BLOB,
  descriptors BLOB,
  cloud_ms REAL NOT NULL DEFAULT 0,
  planarity_ms REAL NOT NULL DEFAULT 0,
  keypoints_ms REAL NOT NULL DEFAULT 0,
  descriptors_ms REAL NOT NULL DEFAULT 0,
  created_at TEXT NOT NULL,
  updated_at TEXT NOT NULL
);
CREATE INDEX models_by_state ON models(state);
CREATE TABLE observations (
  model_id INTEGER NOT NULL REFERENCES models(id),
  seq INTEGER NOT NULL,
  session_id INTEGER NOT NULL REFERENCES sessions(id),
  label INTEGER NOT NULL,
  raw_segment_id INTEGER REFERENCES raw_segments(id),
  T_world_object BLOB NOT NULL,
  T_object_segment BLOB NOT NULL,
  PRIMARY KEY (model_id, seq)
);
CREATE INDEX observations_by_segment ON observations(session_id, label);
CREATE TABLE merge_records (
  id INTEGER PRIMARY KEY AUTOINCREMENT,
  target INTEGER NOT NULL REFERENCES models(id),
  source TEXT NOT NULL,
  transform BLOB NOT NULL,
  icp_rmse_m REAL NOT NULL,
  tsdf_rmse_m REAL NOT NULL,
  tsdf_overlap INTEGER NOT NULL,
  scene_checks INTEGER NOT NULL,
  created_at TEXT NOT NULL
);
CREATE INDEX merge_records_by_target ON merge_records(target);
)sql";

// Version 2: saved live maps of open sessions (a crash loses only the frames after the last
// save).
constexpr const char* kSchemaV2 = R"sql(
CREATE TABLE saved_maps (
  session_id INTEGER PRIMARY KEY REFERENCES sessions(id),
  voxel_size REAL NOT NULL,
  voxels_per_side INTEGER NOT NULL,
  blocks INTEGER NOT NULL,
  frames INTEGER NOT NULL DEFAULT 0,
  updated_at TEXT NOT NULL
);
CREATE TABLE saved_blocks (
  session_id INTEGER NOT NULL REFERENCES saved_maps(session_id) ON DELETE CASCADE,
  bx INTEGER NOT NULL,
  by INTEGER NOT NULL,
  bz INTEGER NOT NULL,
  tsdf BLOB NOT NULL,
  PRIMARY KEY (session_id, bx, by, bz)
);
CREATE TABLE saved_label_blocks (
  session_id INTEGER NOT NULL REFERENCES saved_maps(session_id) ON DELETE CASCADE,
  bx INTEGER NOT NULL,
  by INTEGER NOT NULL,
  bz INTEGER NOT NULL,
  labels BLOB NOT NULL,
  PRIMARY KEY (session_id, bx, by, bz)
);
)sql";

// Room structure: a model's flag, and the depth each raw segment was seen from (the
// noise its planarity and structure tests use).
constexpr const char* kSchemaV3 = R"sql(
ALTER TABLE models ADD COLUMN structure INTEGER NOT NULL DEFAULT 0;
ALTER TABLE raw_segments ADD COLUMN observation_depth_m REAL NOT NULL DEFAULT 0;
)sql";

// Whole objects: the GSM labels a raw segment is made of, comma-separated.
constexpr const char* kSchemaV4 = R"sql(
ALTER TABLE raw_segments ADD COLUMN parts TEXT NOT NULL DEFAULT '';
)sql";

// Parts with geometry: the part (GSM label) of each of a raw segment's voxels, as an
// index blob aligned with raw_segments.voxels; NULL when not recorded.
constexpr const char* kSchemaV5 = R"sql(
ALTER TABLE raw_segments ADD COLUMN voxel_parts BLOB;
)sql";

}  // namespace

const std::vector<Migration>& schemaMigrations() {
  static const std::vector<Migration> migrations = {
      {1, "sessions, scene maps, raw segments, models, observations, merge records", kSchemaV1},
      {2, "saved live maps of open sessions", kSchemaV2},
      {3, "room structure: models.structure, raw_segments.observation_depth_m", kSchemaV3},
      {4, "whole objects: raw_segments.parts", kSchemaV4},
      {5, "parts with geometry: raw_segments.voxel_parts", kSchemaV5},
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
