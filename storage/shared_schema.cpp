#include "storage/shared_schema.h"

#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_replace.h"
#include "absl/strings/string_view.h"

namespace objdb::storage {
namespace {

// The tables, with the dialect's words as placeholders ($ID, $INT, $REAL, $BLOB, $BOOL, $FALSE,
// $ROW_ID: SqlDialect) and $COLUMNS where a table's further columns go. Times are ISO-8601 UTC
// text; binary columns are blobs of storage/blob_codec.h.
constexpr const char* kSessions = R"sql(CREATE TABLE sessions (
  id $ID,
  name TEXT NOT NULL UNIQUE,
  intrinsics TEXT NOT NULL DEFAULT '',
  params TEXT NOT NULL DEFAULT '',
  started_at TEXT NOT NULL,
  ended_at TEXT,
  state TEXT NOT NULL CHECK (state IN ('open', 'ended', 'interrupted')),
  frames $INT NOT NULL DEFAULT 0
);
)sql";

// A map ($MAPS) and one of its block tables ($BLOCKS, blob column $BLOB_COLUMN).
constexpr const char* kMap = R"sql(CREATE TABLE $MAPS (
  session_id $INT PRIMARY KEY REFERENCES sessions(id),
  voxel_size $REAL NOT NULL,
  voxels_per_side $INT NOT NULL,
  blocks $INT NOT NULL,
$COLUMNS  updated_at TEXT NOT NULL
);
)sql";
constexpr const char* kBlocks = R"sql(CREATE TABLE $BLOCKS (
$ROW_ID  session_id $INT NOT NULL REFERENCES $MAPS(session_id) ON DELETE CASCADE,
  bx INTEGER NOT NULL,
  by INTEGER NOT NULL,
  bz INTEGER NOT NULL,
  $BLOB_COLUMN $BLOB NOT NULL,
  PRIMARY KEY (session_id, bx, by, bz)
);
)sql";

constexpr const char* kRawSegments = R"sql(CREATE TABLE raw_segments (
  id $ID,
  session_id $INT NOT NULL REFERENCES sessions(id),
  label $INT NOT NULL,
  pose $BLOB NOT NULL,
  grid $BLOB NOT NULL,
  voxels $BLOB NOT NULL,
  extraction_frame $INT NOT NULL,
$COLUMNS  extracted_at TEXT NOT NULL,
  UNIQUE (session_id, label)
);
)sql";

constexpr const char* kModels = R"sql(CREATE TABLE models (
  id $ID,
  state TEXT NOT NULL CHECK (state IN ('active', 'merged', 'removed')),
  merged_into $INT REFERENCES models(id),
  planar $BOOL NOT NULL,
$COLUMNS  plane_inlier_ratio $REAL NOT NULL,
  num_points $INT NOT NULL,
  num_keypoints $INT NOT NULL,
  voxel_size $REAL,
  bbox_min_x $REAL, bbox_min_y $REAL, bbox_min_z $REAL,
  bbox_max_x $REAL, bbox_max_y $REAL, bbox_max_z $REAL,
  grid $BLOB,
  surface_voxels $BLOB,
  cloud $BLOB,
  keypoints $BLOB,
  descriptors $BLOB,
  cloud_ms $REAL NOT NULL DEFAULT 0,
  planarity_ms $REAL NOT NULL DEFAULT 0,
  keypoints_ms $REAL NOT NULL DEFAULT 0,
  descriptors_ms $REAL NOT NULL DEFAULT 0,
  created_at TEXT NOT NULL,
  updated_at TEXT NOT NULL
);
CREATE INDEX models_by_state ON models(state);
)sql";

constexpr const char* kObservationsAndMerges = R"sql(CREATE TABLE observations (
$ROW_ID  model_id $INT NOT NULL REFERENCES models(id),
  seq $INT NOT NULL,
  session_id $INT NOT NULL REFERENCES sessions(id),
  label $INT NOT NULL,
  raw_segment_id $INT REFERENCES raw_segments(id),
  T_world_object $BLOB NOT NULL,
  T_object_segment $BLOB NOT NULL,
  PRIMARY KEY (model_id, seq)
);
CREATE INDEX observations_by_segment ON observations(session_id, label);
CREATE TABLE merge_records (
  id $ID,
  target $INT NOT NULL REFERENCES models(id),
  source TEXT NOT NULL,
  transform $BLOB NOT NULL,
  icp_rmse_m $REAL NOT NULL,
  tsdf_rmse_m $REAL NOT NULL,
  tsdf_overlap $INT NOT NULL,
  scene_checks $INT NOT NULL,
  created_at TEXT NOT NULL
);
CREATE INDEX merge_records_by_target ON merge_records(target);
)sql";

// The columns the SQLite schema added after its first version, in the order it added them.
struct AddedColumn {
  int version;  // the SQLite schema version that added it
  const char* table;
  const char* definition;
};
constexpr AddedColumn kAddedColumns[] = {
    // Room structure: a model's flag (never matched), and the depth each raw segment was seen
    // from (the noise its planarity and structure tests use).
    {3, "models", "structure $BOOL NOT NULL DEFAULT $FALSE"},
    {3, "raw_segments", "observation_depth_m $REAL NOT NULL DEFAULT 0"},
    // Whole objects: the GSM labels a raw segment is made of, comma-separated.
    {4, "raw_segments", "parts TEXT NOT NULL DEFAULT ''"},
    // Parts with geometry: the part (GSM label) of each of a raw segment's voxels, as an index
    // blob aligned with raw_segments.voxels; NULL when not recorded.
    {5, "raw_segments", "voxel_parts $BLOB"},
    // Sessions that outlive their server: the client's description and the running counters
    // (Store::storeSessionCounters), empty when never stored.
    {6, "sessions", "client TEXT NOT NULL DEFAULT ''"},
    {6, "sessions", "counters TEXT NOT NULL DEFAULT ''"},
    // Two-stage retrieval: a model's global descriptor (the short list's key, read when a
    // database opens instead of every local descriptor); NULL until computed.
    {7, "models", "global_descriptor $BLOB"},
};

// `ddl` in dialect `d`, with `more` placeholders replaced too.
std::string inDialect(absl::string_view ddl, const SqlDialect& d,
                      std::vector<std::pair<absl::string_view, absl::string_view>> more = {}) {
  more.insert(more.end(), {{"$ID", d.id},
                           {"$INT", d.integer},
                           {"$REAL", d.real},
                           {"$BLOB", d.blob},
                           {"$BOOL", d.boolean},
                           {"$FALSE", d.false_value},
                           {"$ROW_ID", d.row_id}});
  return absl::StrReplaceAll(ddl, more);
}

// Table `table` of template `ddl`, with the columns added up to SQLite schema `added_up_to` in
// place (0: none).
std::string withAddedColumns(const SqlDialect& d, absl::string_view ddl, absl::string_view table,
                             int added_up_to) {
  std::string columns;
  for (const AddedColumn& c : kAddedColumns) {
    if (c.version <= added_up_to && c.table == table) {
      absl::StrAppend(&columns, "  ", inDialect(c.definition, d), ",\n");
    }
  }
  return inDialect(ddl, d, {{"$COLUMNS", columns}});
}

}  // namespace

std::string sessionsTable(const SqlDialect& d) { return inDialect(kSessions, d); }

std::string mapTables(const SqlDialect& d, const MapTables& tables) {
  const std::string frames =
      tables.has_frames ? inDialect("  frames $INT NOT NULL DEFAULT 0,\n", d) : std::string();
  std::string out = inDialect(kMap, d, {{"$MAPS", tables.maps}, {"$COLUMNS", frames}});
  for (const auto& [blocks, column] :
       {std::pair{tables.blocks, "tsdf"}, std::pair{tables.label_blocks, "labels"}}) {
    absl::StrAppend(
        &out, inDialect(kBlocks, d,
                        {{"$BLOCKS", blocks}, {"$MAPS", tables.maps}, {"$BLOB_COLUMN", column}}));
  }
  return out;
}

std::string segmentAndModelTables(const SqlDialect& d, int added_up_to) {
  return absl::StrCat(withAddedColumns(d, kRawSegments, "raw_segments", added_up_to),
                      withAddedColumns(d, kModels, "models", added_up_to),
                      inDialect(kObservationsAndMerges, d));
}

std::string addedColumns(const SqlDialect& d, int version) {
  std::string out;
  for (const AddedColumn& c : kAddedColumns) {
    if (c.version == version) {
      absl::StrAppend(&out, "ALTER TABLE ", c.table, " ADD COLUMN ", inDialect(c.definition, d),
                      ";\n");
    }
  }
  return out;
}

}  // namespace objdb::storage
