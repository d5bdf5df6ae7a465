// What the schemas of both backends share (storage/sqlite/schema.h, storage/postgres/pg_schema.h):
// the migration steps, and the tables of the data model, described once and written out in each
// engine's SQL dialect (its type names, and how ids are made).
#pragma once

#include <string>

namespace objdb::storage {

struct Migration {
  int version;              // the schema version after this step (1, 2, ...)
  std::string description;  // one line, shown in logs
  std::string sql;          // DDL/DML run in the step's transaction
};

struct SchemaState {
  int version_before = 0;  // 0 for a new file or database
  int version_after = 0;
  bool created = false;  // the database was empty and got the schema
};

// The tables of one kind of stored map: a session's scene map, or its saved live map.
struct MapTables {
  const char* what;  // in messages: "scene" or "saved map"
  const char* maps;
  const char* blocks;
  const char* label_blocks;
  bool has_frames;  // the map table has a `frames` column
};
inline constexpr MapTables kSceneTables{"scene", "scene_maps", "scene_blocks", "scene_label_blocks",
                                        false};
inline constexpr MapTables kSavedTables{"saved map", "saved_maps", "saved_blocks",
                                        "saved_label_blocks", true};

// An engine's words for what the shared tables need.
struct SqlDialect {
  const char* id;       // a table's own id: its primary key, never reused
  const char* integer;  // 64-bit integer
  const char* real;     // double
  const char* blob;     // bytes
  const char* boolean;
  const char* false_value;  // the boolean's default
  // The first column line of block and observation rows: an id of their own (for messages),
  // "" where the engine has one already (SQLite's rowid).
  const char* row_id;
};

// CREATE TABLE (and CREATE INDEX) statements in dialect `d`, each ending in ";\n".
std::string sessionsTable(const SqlDialect& d);
// A map's table and its TSDF and label block tables.
std::string mapTables(const SqlDialect& d, const MapTables& tables);
// raw_segments, models, observations and merge_records with their indexes, with the columns the
// SQLite schema added up to its version `added_up_to` in place (0: as its version 1 had them).
// The SQL of a schema version must never change: each caller names the version it froze.
std::string segmentAndModelTables(const SqlDialect& d, int added_up_to);
// The ALTER TABLE statements by which the SQLite schema's version `version` added columns to the
// tables of segmentAndModelTables().
std::string addedColumns(const SqlDialect& d, int version);

}  // namespace objdb::storage
