#include "storage/sqlite/sqlite_store.h"

#include <fstream>
#include <sstream>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <sqlite3.h>

#include "tests/storage/store_fixtures.h"
#include "tests/support/temp_dir.h"

namespace objdb::storage {
namespace {

using objdb::testing::diffLayers;
using objdb::testing::diffModels;
using objdb::testing::makeRawSegment;
using objdb::testing::makeStoreModel;
using objdb::testing::TempDir;
using ::testing::HasSubstr;

std::string readFile(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// Raw SQL on the file, outside the store (to damage it the way a disk or a person would).
void rawSql(const std::filesystem::path& path, const std::string& sql) {
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
  char* error = nullptr;
  EXPECT_EQ(sqlite3_exec(db, sql.c_str(), nullptr, nullptr, &error), SQLITE_OK)
      << (error ? error : "");
  sqlite3_free(error);
  sqlite3_close(db);
}

// Flips one byte in the middle of a blob column of one row.
void flipBlobByte(const std::filesystem::path& path, const std::string& table,
                  const std::string& column, int64_t rowid) {
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
  sqlite3_stmt* s = nullptr;
  const std::string select = "SELECT " + column + " FROM " + table + " WHERE rowid = ?";
  ASSERT_EQ(sqlite3_prepare_v2(db, select.c_str(), -1, &s, nullptr), SQLITE_OK);
  sqlite3_bind_int64(s, 1, rowid);
  ASSERT_EQ(sqlite3_step(s), SQLITE_ROW);
  std::string blob(static_cast<const char*>(sqlite3_column_blob(s, 0)),
                   size_t(sqlite3_column_bytes(s, 0)));
  sqlite3_finalize(s);
  blob[blob.size() - blob.size() / 3] ^= 0x01;
  const std::string update = "UPDATE " + table + " SET " + column + " = ? WHERE rowid = ?";
  ASSERT_EQ(sqlite3_prepare_v2(db, update.c_str(), -1, &s, nullptr), SQLITE_OK);
  sqlite3_bind_blob(s, 1, blob.data(), int(blob.size()), SQLITE_TRANSIENT);
  sqlite3_bind_int64(s, 2, rowid);
  ASSERT_EQ(sqlite3_step(s), SQLITE_DONE);
  sqlite3_finalize(s);
  sqlite3_close(db);
}

std::unique_ptr<SqliteStore> openStore(const std::filesystem::path& path,
                                       SqliteStoreOptions options = {}) {
  auto store = SqliteStore::open(path.string(), options);
  EXPECT_TRUE(store.ok()) << store.status();
  return store.ok() ? std::move(*store) : nullptr;
}

TEST(SqliteStore, ANewFileGetsTheCurrentSchemaInWalMode) {
  TempDir dir;
  auto store = openStore(dir / "db.sqlite");
  ASSERT_NE(store, nullptr);
  EXPECT_TRUE(store->schema().created);
  EXPECT_EQ(store->schema().version_after, currentSchemaVersion());
  EXPECT_TRUE(store->modelIds().value().empty());
  store.reset();
  // Journal mode is persistent in the file.
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open((dir / "db.sqlite").c_str(), &db), SQLITE_OK);
  sqlite3_stmt* s = nullptr;
  ASSERT_EQ(sqlite3_prepare_v2(db, "PRAGMA journal_mode", -1, &s, nullptr), SQLITE_OK);
  ASSERT_EQ(sqlite3_step(s), SQLITE_ROW);
  EXPECT_STREQ(reinterpret_cast<const char*>(sqlite3_column_text(s, 0)), "wal");
  sqlite3_finalize(s);
  sqlite3_close(db);
}

TEST(SqliteStore, AFlippedBlobByteFailsThatRowOnly) {
  TempDir dir;
  const auto path = dir / "db.sqlite";
  std::vector<model::ObjectModel> originals;
  {
    auto store = openStore(path);
    for (uint32_t seed = 1; seed <= 4; ++seed) {
      model::ObjectModel m = makeStoreModel(seed, 2);
      m.id = store->addModel(model::cloneModel(m)).value();
      originals.push_back(std::move(m));
    }
    ASSERT_TRUE(store->putScene("s0", std::make_shared<const tsdf::TsdfLayer>(originals[0].grid.clone())).ok());
  }
  flipBlobByte(path, "models", "descriptors", 2);
  flipBlobByte(path, "models", "grid", 3);
  auto store = openStore(path);
  const auto two = store->model(2);
  ASSERT_FALSE(two.ok());
  EXPECT_EQ(two.status().code(), absl::StatusCode::kDataLoss);
  EXPECT_THAT(two.status().message(), HasSubstr("models row 2, column descriptors"));
  EXPECT_THAT(two.status().message(), HasSubstr("checksum mismatch (expected"));
  EXPECT_THAT(store->model(3).status().message(), HasSubstr("models row 3, column grid"));
  EXPECT_EQ(diffModels(*store->model(1).value(), originals[0]), "");
  EXPECT_EQ(diffModels(*store->model(4).value(), originals[3]), "");
  EXPECT_EQ(store->modelIds().value().size(), 4u);
  // The prefilter's index leaves out the one whose descriptors are damaged and says why.
  const auto entries = store->matchEntries(true).value();
  EXPECT_EQ(entries.entries.size(), 3u);
  ASSERT_EQ(entries.skipped.size(), 1u);
  EXPECT_THAT(entries.skipped[0].message(), HasSubstr("models row 2"));
  const auto report = store->check().value();
  EXPECT_TRUE(report.engine_findings.empty());
  ASSERT_EQ(report.damaged.size(), 2u);
  EXPECT_EQ(report.damaged[0].table, "models");
  EXPECT_EQ(report.damaged[0].row, 3);
  EXPECT_EQ(report.damaged[0].column, "grid");
  EXPECT_EQ(report.damaged[1].row, 2);
  EXPECT_EQ(report.damaged[1].column, "descriptors");
  EXPECT_GT(report.blobs_checked, 20u);

  // A damaged scene block is named by session and block.
  store.reset();
  flipBlobByte(path, "scene_blocks", "tsdf", 1);
  store = openStore(path);
  const auto scene = store->scene("s0");
  ASSERT_FALSE(scene.ok());
  EXPECT_THAT(scene.status().message(), HasSubstr("scene of session s0, block"));
  EXPECT_EQ(store->check().value().damaged.size(), 3u);
}

// A raw segment whose recorded voxel parts are not all among its parts (issue 47: ListObjects
// with parts failed with DATA_LOSS while `objdb db check` said ok). Reading it names the row and
// the part, and the check reports it: no single column shows it, so the check reads them together.
TEST(SqliteStore, AVoxelPartThatIsNotOneOfTheSegmentsPartsIsDamageTheCheckReports) {
  TempDir dir;
  const auto path = dir / "db.sqlite";
  {
    auto store = openStore(path);
    auto segment = makeRawSegment("session_1", 68, 1);
    segment.parts = {2, 3};
    for (size_t i = 0; i < segment.voxels.size(); ++i) segment.voxel_parts.push_back(i % 2 ? 3 : 2);
    ASSERT_TRUE(store->putRawSegment(segment).ok());
    EXPECT_TRUE(store->check().value().ok());
  }
  rawSql(path, "UPDATE raw_segments SET parts = '2'");
  auto store = openStore(path);
  const auto read = store->rawSegment({"session_1", 68});
  ASSERT_FALSE(read.ok());
  EXPECT_EQ(read.status().code(), absl::StatusCode::kDataLoss);
  EXPECT_THAT(read.status().message(), HasSubstr("raw_segments row 1, column voxel_parts"));
  EXPECT_THAT(read.status().message(),
              HasSubstr("a voxel of part 3, which is not one of its parts (2)"));
  const auto report = store->check().value();
  ASSERT_EQ(report.damaged.size(), 1u);
  EXPECT_EQ(report.damaged[0].table, "raw_segments");
  EXPECT_EQ(report.damaged[0].row, 1);
  EXPECT_EQ(report.damaged[0].column, "voxel_parts");
  EXPECT_THAT(report.damaged[0].problem, HasSubstr("part 3"));
}

TEST(SqliteStore, WrongFilesAreRefusedUntouched) {
  TempDir dir;
  {
    auto store = openStore(dir / "good.sqlite");
    for (uint32_t seed = 1; seed <= 20; ++seed) ASSERT_TRUE(store->addModel(makeStoreModel(seed, 3)).ok());
  }
  // Text file.
  ASSERT_TRUE(objdb::testing::writeTextFile(dir / "notes.txt", std::string(5000, 'x') + "\n"));
  auto text = SqliteStore::open((dir / "notes.txt").string());
  ASSERT_FALSE(text.ok());
  EXPECT_EQ(text.status().code(), absl::StatusCode::kDataLoss);
  EXPECT_THAT(text.status().message(), HasSubstr("not a database"));
  EXPECT_EQ(readFile(dir / "notes.txt"), std::string(5000, 'x') + "\n");

  // Another application's SQLite database.
  rawSql(dir / "other.sqlite", "CREATE TABLE t(x); INSERT INTO t VALUES (1);");
  const std::string other_before = readFile(dir / "other.sqlite");
  auto other = SqliteStore::open((dir / "other.sqlite").string());
  ASSERT_FALSE(other.ok());
  EXPECT_EQ(other.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_THAT(other.status().message(), HasSubstr("another application"));
  EXPECT_EQ(readFile(dir / "other.sqlite"), other_before);

  // A newer schema.
  std::filesystem::copy_file(dir / "good.sqlite", dir / "future.sqlite");
  rawSql(dir / "future.sqlite", "PRAGMA user_version = 99;");
  const std::string future_before = readFile(dir / "future.sqlite");
  auto future = SqliteStore::open((dir / "future.sqlite").string());
  ASSERT_FALSE(future.ok());
  EXPECT_EQ(future.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_THAT(future.status().message(), HasSubstr("schema version 99, newer than this build"));
  EXPECT_EQ(readFile(dir / "future.sqlite"), future_before);

  // Truncated to half.
  std::filesystem::copy_file(dir / "good.sqlite", dir / "half.sqlite");
  std::filesystem::resize_file(dir / "half.sqlite", std::filesystem::file_size(dir / "half.sqlite") / 2);
  const std::string half_before = readFile(dir / "half.sqlite");
  auto half = SqliteStore::open((dir / "half.sqlite").string());
  ASSERT_FALSE(half.ok());
  EXPECT_EQ(half.status().code(), absl::StatusCode::kDataLoss);
  EXPECT_THAT(half.status().message(), HasSubstr("half.sqlite"));
  EXPECT_EQ(readFile(dir / "half.sqlite"), half_before);

  // Missing file with create_if_missing off; a directory.
  SqliteStoreOptions no_create;
  no_create.create_if_missing = false;
  EXPECT_EQ(SqliteStore::open((dir / "none.sqlite").string(), no_create).status().code(),
            absl::StatusCode::kNotFound);
  EXPECT_EQ(SqliteStore::open(dir.path().string()).status().code(),
            absl::StatusCode::kFailedPrecondition);
  SqliteStoreOptions bad;
  bad.synchronous = "OFF";
  EXPECT_THAT(SqliteStore::open((dir / "x.sqlite").string(), bad).status().message(),
              HasSubstr("synchronous must be FULL or NORMAL"));
}

TEST(SqliteStore, ReadOnlyStoresReadAndRefuseWrites) {
  TempDir dir;
  { ASSERT_TRUE(openStore(dir / "db.sqlite")->addModel(makeStoreModel(1, 1)).ok()); }
  SqliteStoreOptions options;
  options.read_only = true;
  auto store = openStore(dir / "db.sqlite", options);
  ASSERT_NE(store, nullptr);
  EXPECT_TRUE(store->model(1).ok());
  EXPECT_EQ(store->addModel(makeStoreModel(2, 1)).status().code(),
            absl::StatusCode::kFailedPrecondition);
}

// What a file of an older schema holds must survive its migration: a session and its scene map
// (the scene creates its session row with the columns every schema since the first has; this
// build's session, model and raw-segment writes need the current schema's columns).
void addSessionWithScene(SqliteStore* store, const std::string& name) {
  ASSERT_TRUE(store->putScene(name, std::make_shared<const tsdf::TsdfLayer>(
                                        makeStoreModel(1, 2).grid.clone())).ok());
}

// The session's scene by its name; with `current_schema`, its row as sessions() lists it too
// (which reads the current schema's columns).
void expectSessionWithScene(const SqliteStore& store, const std::string& name,
                            bool current_schema = false) {
  if (current_schema) {
    const auto sessions = store.sessions();
    ASSERT_TRUE(sessions.ok()) << sessions.status();
    ASSERT_EQ(sessions->size(), 1u);
    EXPECT_EQ(sessions->front().name, name);
    EXPECT_TRUE(sessions->front().counters_json.empty());  // none stored: unknown
  }
  const auto scene = store.scene(name);
  ASSERT_TRUE(scene.ok() && *scene != nullptr);
  EXPECT_EQ((*scene)->numBlocks(), makeStoreModel(1, 2).grid.numBlocks());
}

TEST(SqliteStore, OlderSchemasAreMigratedAndAFailedMigrationChangesNothing) {
  TempDir dir;
  const auto path = (dir / "db.sqlite").string();
  std::vector<Migration> v1 = {schemaMigrations().front()};
  {
    auto store = SqliteStore::open(path, {}, v1);
    ASSERT_TRUE(store.ok()) << store.status();
    addSessionWithScene(store->get(), "monday");
  }
  // A step that fails half way rolls back: the file stays at version 1 with its data.
  std::vector<Migration> broken = v1;
  broken.push_back({2, "broken", "ALTER TABLE sessions ADD COLUMN note TEXT; SELECT * FROM nowhere;"});
  auto failed = SqliteStore::open(path, {}, broken);
  ASSERT_FALSE(failed.ok());
  EXPECT_THAT(failed.status().message(), HasSubstr("migrating to schema 2"));
  {
    auto store = SqliteStore::open(path, {}, v1);
    ASSERT_TRUE(store.ok()) << store.status();
    EXPECT_EQ((*store)->schema().version_after, 1);
    expectSessionWithScene(**store, "monday");
  }
  std::vector<Migration> v2 = v1;
  v2.push_back({2, "session notes", "ALTER TABLE sessions ADD COLUMN note TEXT NOT NULL DEFAULT '';"});
  auto migrated = SqliteStore::open(path, {}, v2);
  ASSERT_TRUE(migrated.ok()) << migrated.status();
  EXPECT_EQ((*migrated)->schema().version_before, 1);
  EXPECT_EQ((*migrated)->schema().version_after, 2);
  expectSessionWithScene(**migrated, "monday");
}

// One writer per file (the server and `objdb ingest` keep in-memory copies of what the file
// holds): a second writable open is refused while the first is open, readers are not, and the
// lock goes with the store.
TEST(SqliteStore, ASecondWriterOnTheSameFileIsRefusedUntilTheFirstCloses) {
  TempDir dir;
  const std::string path = (dir / "db.sqlite").string();
  auto first = SqliteStore::open(path);
  ASSERT_TRUE(first.ok()) << first.status();
  ASSERT_TRUE((*first)->addModel(makeStoreModel(1, 1)).ok());
  const auto second = SqliteStore::open(path);
  ASSERT_FALSE(second.ok());
  EXPECT_EQ(second.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_THAT(second.status().message(), HasSubstr("open for writing by another objdb store"));
  SqliteStoreOptions read_only;
  read_only.read_only = true;
  const auto reader = SqliteStore::open(path, read_only);
  ASSERT_TRUE(reader.ok()) << reader.status();
  EXPECT_EQ((*reader)->modelIds().value().size(), 1u);
  first->reset();
  const auto after = SqliteStore::open(path);
  ASSERT_TRUE(after.ok()) << after.status();
  EXPECT_TRUE((*after)->addModel(makeStoreModel(2, 1)).ok());
}

// This build's own migrations: a file of schema 1 (before saved live maps and room structure)
// opens as the current schema with its sessions and scenes, and takes models (structure
// flag and observation depth round-trip), raw segments and saved maps.
TEST(SqliteStore, AFileOfTheFirstSchemaIsMigratedToTheCurrentOne) {
  TempDir dir;
  const auto path = (dir / "db.sqlite").string();
  {
    auto store = SqliteStore::open(path, {}, {schemaMigrations().front()});
    ASSERT_TRUE(store.ok()) << store.status();
    addSessionWithScene(store->get(), "s");
  }
  auto store = SqliteStore::open(path);
  ASSERT_TRUE(store.ok()) << store.status();
  EXPECT_EQ((*store)->schema().version_before, 1);
  EXPECT_EQ((*store)->schema().version_after, currentSchemaVersion());
  expectSessionWithScene(**store, "s", /*current_schema=*/true);
  model::ObjectModel structure = makeStoreModel(1, 2);
  structure.structure = true;
  const auto id = (*store)->addModel(makeStoreModel(1, 2));
  const auto wall = (*store)->addModel(std::move(structure));
  ASSERT_TRUE(id.ok() && wall.ok());
  EXPECT_FALSE((*store)->model(*id).value()->structure);
  EXPECT_TRUE((*store)->model(*wall).value()->structure);
  database::RawSegmentRecord segment;
  segment.key = {"s", 4};
  segment.grid = std::make_shared<const tsdf::TsdfLayer>(makeStoreModel(1, 2).grid.clone());
  segment.voxels = {tsdf::VoxelIndex(1, 2, 3)};
  segment.observation_depth_m = 2.75f;
  segment.parts = {4, 7};
  segment.voxel_parts = {7};
  ASSERT_TRUE((*store)->putRawSegment(segment).ok());
  EXPECT_EQ((*store)->rawSegment({"s", 4}).value()->voxel_parts, (std::vector<uint32_t>{7}));
  EXPECT_FLOAT_EQ((*store)->rawSegment({"s", 4}).value()->observation_depth_m, 2.75f);
  EXPECT_EQ((*store)->rawSegment({"s", 4}).value()->parts, (std::vector<uint32_t>{4, 7}));
  const model::ObjectModel source = makeStoreModel(1, 2);
  ASSERT_TRUE((*store)->putSavedMap("s", 3, source.grid, {}).ok());
  EXPECT_EQ((*store)->savedMap("s").value().frames, 3);
  EXPECT_TRUE((*store)->check().value().ok());
}

}  // namespace
}  // namespace objdb::storage
