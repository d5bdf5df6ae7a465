// `objdb db`: check / stats / models / export on a database written through the store, and its
// answers for damaged and foreign files.
#include <gtest/gtest.h>
#include <sqlite3.h>

#include <filesystem>
#include <string>
#include <tuple>

#include "core/common/params_io.h"
#include "core/database/object_database.h"
#include "core/io/mesh_io.h"
#include "core/tsdf/mesh_extraction.h"
#include "storage/sqlite/sqlite_store.h"
#include "tests/storage/store_fixtures.h"
#include "tests/support/object_scenes.h"
#include "tests/support/subprocess.h"
#include "tests/support/temp_dir.h"

namespace objdb {
namespace {

using testing::ProcessResult;
using testing::runProcess;
namespace fs = std::filesystem;

const std::string kObjdb = OBJDB_CLIENT_BINARY;

// A database with three models (the second merged once) and a scene.
void writeDatabase(const fs::path& path) {
  auto store = storage::SqliteStore::open(path.string()).value();
  for (uint32_t seed : {1u, 2u, 3u}) ASSERT_TRUE(store->addModel(testing::makeStoreModel(seed, 2)).ok());
  model::ObjectModel merged = testing::makeStoreModel(4, 3);
  merged.id = 2;
  database::MergeRecord record;
  record.target = 2;
  record.source = "segment s2/9";
  ASSERT_TRUE(store->replaceModel(std::move(merged), record).ok());
  ASSERT_TRUE(store->putScene("s0", std::make_shared<const tsdf::TsdfLayer>(
                                        testing::makeStoreModel(5, 1).grid.clone())).ok());
}

TEST(DbCommand, ChecksDescribesAndExports) {
  testing::TempDir dir;
  const fs::path db = dir / "objects.sqlite";
  writeDatabase(db);
  ProcessResult r = runProcess({kObjdb, "db", "check", "--db", db.string()});
  EXPECT_EQ(r.exit_code, 0) << r.out << r.err;
  EXPECT_NE(r.out.find("0 damaged, 0 engine findings: ok"), std::string::npos) << r.out;

  r = runProcess({kObjdb, "db", "stats", "--db", db.string()});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("models: 3 active"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("merge_records"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("session s2"), std::string::npos) << r.out;

  r = runProcess({kObjdb, "db", "models", "--db", db.string()});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("s0/"), std::string::npos) << r.out;

  const fs::path cloud = dir / "model2.ply";
  r = runProcess({kObjdb, "db", "export", "--db", db.string(), "--model", "2", "--out",
                  cloud.string(), "--what", "cloud"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("cloud with"), std::string::npos) << r.out;
  const auto stored = storage::SqliteStore::open(db.string()).value()->model(2).value();
  const auto read = io::readMesh(cloud);
  ASSERT_TRUE(read.ok()) << read.status();
  EXPECT_EQ(read->vertices.size(), stored->cloud.points.size());
  EXPECT_EQ(read->vertices, stored->cloud.points);
  // The default is the mesh, as `objdb remote object` writes (issue 47).
  r = runProcess({kObjdb, "db", "export", "--db", db.string(), "--model", "2", "--out",
                  (dir / "mesh2.ply").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("model 2: mesh with"), std::string::npos) << r.out;

  r = runProcess({kObjdb, "db", "export", "--db", db.string(), "--model", "7", "--out", cloud.string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("no object model 7"), std::string::npos) << r.err;
}

TEST(DbCommand, BacksUpIntoANewFileThatReadsTheSameAndNeverOverwrites) {
  testing::TempDir dir;
  const fs::path db = dir / "objects.sqlite";
  writeDatabase(db);
  const fs::path copy = dir / "copy.sqlite";
  ProcessResult r = runProcess({kObjdb, "db", "backup", "--db", db.string(), "--out", copy.string()});
  EXPECT_EQ(r.exit_code, 0) << r.out << r.err;
  EXPECT_NE(r.out.find("backed up to " + copy.string()), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("0 damaged, 0 engine findings: ok"), std::string::npos) << r.out;
  for (const auto& entry : fs::directory_iterator(dir.path())) {
    EXPECT_EQ(entry.path().string().find(".partial"), std::string::npos) << entry.path();
  }
  {
    auto original = storage::SqliteStore::open(db.string()).value();
    auto copied = storage::SqliteStore::open(copy.string()).value();
    const std::vector<int64_t> ids = original->modelIds().value();
    ASSERT_EQ(copied->modelIds().value(), ids);
    for (int64_t id : ids) {
      EXPECT_EQ(testing::diffModels(*copied->model(id).value(), *original->model(id).value()), "")
          << id;
    }
    EXPECT_EQ(copied->mergeRecords().value().size(), 1u);
    EXPECT_NE(copied->scene("s0").value(), nullptr);
  }
  // Never over an existing file; --out is required.
  const auto size = fs::file_size(copy);
  r = runProcess({kObjdb, "db", "backup", "--db", db.string(), "--out", copy.string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("exists"), std::string::npos) << r.err;
  EXPECT_EQ(fs::file_size(copy), size);
  r = runProcess({kObjdb, "db", "backup", "--db", db.string()});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("backup needs --out NEW_FILE"), std::string::npos) << r.err;
}

TEST(DbCommand, CheckListsDamagedRowsAndExitsOne) {
  testing::TempDir dir;
  const fs::path db = dir / "objects.sqlite";
  writeDatabase(db);
  sqlite3* raw = nullptr;
  ASSERT_EQ(sqlite3_open(db.c_str(), &raw), SQLITE_OK);
  // Flip one byte at the end of model 3's cloud blob.
  ASSERT_EQ(sqlite3_exec(raw,
                         "UPDATE models SET cloud = substr(cloud, 1, length(cloud) - 1) || "
                         "CAST(char((unicode(substr(cloud, -1)) + 1) % 128) AS BLOB) WHERE id = 3",
                         nullptr, nullptr, nullptr),
            SQLITE_OK);
  sqlite3_close(raw);
  ProcessResult r = runProcess({kObjdb, "db", "check", "--db", db.string()});
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_NE(r.out.find("damaged: models row 3, column cloud"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("1 damaged"), std::string::npos) << r.out;
  r = runProcess({kObjdb, "db", "models", "--db", db.string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.out.find("3 unreadable"), std::string::npos) << r.out;
}

// The object seen from its front on Monday and from its back on Tuesday, merged by the database
// into one model (core/completion's test scene), in a SQLite file.
void writeTwoSessions(const fs::path& path) {
  using namespace objdb::testing;
  const PlacedShape monday{boxWithBall(), poseXyYaw(0.3, -0.2, 0.3)};
  const PlacedShape tuesday{boxWithBall(), poseXyYaw(-0.5, 0.4, 2.0)};
  const View front{-1.0f, 0.12f}, back{-0.12f, 1.0f};
  Params params;
  params.tsdf.voxel_size_m = kSceneVoxel;
  auto store = storage::SqliteStore::open(path.string()).value();
  for (const auto& [name, shape, view] :
       {std::tuple{"monday", monday, front}, std::tuple{"tuesday", tuesday, back}}) {
    storage::SessionInfo info;
    info.name = name;
    info.params_json = paramsToJson(params);
    ASSERT_TRUE(store->beginSession(info).ok());
    ASSERT_TRUE(store->putScene(name, std::make_shared<const tsdf::TsdfLayer>(
                                          sceneGrid({shape}, {view}))).ok());
  }
  auto db = database::ObjectDatabase::create(params, store.get()).value();
  ASSERT_TRUE(db->insertSegment("monday", rawSegment(1, monday, front)).ok());
  auto merged = db->insertSegment("tuesday", rawSegment(1, tuesday, back));
  ASSERT_TRUE(merged.ok() && merged->merged);
}

TEST(DbCommand, CompletesASessionsSceneWithTheMergedModels) {
  testing::TempDir dir;
  const fs::path db = dir / "objects.sqlite";
  ASSERT_NO_FATAL_FAILURE(writeTwoSessions(db));
  const fs::path out = dir / "monday.ply";
  ProcessResult r = runProcess(
      {kObjdb, "db", "complete", "--db", db.string(), "--session", "monday", "--out", out.string()});
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  EXPECT_NE(r.out.find("the session's stored parameters"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("1 of 1 placements verified"), std::string::npos) << r.out;
  const auto completed = io::readMesh(out);
  ASSERT_TRUE(completed.ok()) << completed.status();
  // Monday's own map, meshed the same way: the completed mesh has more surface (the back).
  const auto scene = storage::SqliteStore::open(db.string()).value()->scene("monday").value();
  EXPECT_GT(completed->surfaceArea(), 1.2 * tsdf::extractMesh(*scene, 3.0f).surfaceArea());

  // Thresholds from --config on top: an overlap no placement reaches rejects it, nothing is filled.
  ASSERT_TRUE(testing::writeTextFile(dir / "strict.json",
                                     R"({"merging": {"tsdf_min_overlap_voxels": 1e9}})"));
  r = runProcess({kObjdb, "db", "complete", "--db", db.string(), "--session", "monday", "--out",
                  out.string(), "--config", (dir / "strict.json").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("rejected: overlap"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("0 of 1 placements verified, 0 voxels filled"), std::string::npos) << r.out;

  r = runProcess({kObjdb, "db", "complete", "--db", db.string(), "--session", "friday", "--out",
                  out.string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("no session friday"), std::string::npos) << r.err;
  r = runProcess({kObjdb, "db", "complete", "--db", db.string(), "--out", out.string()});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("complete needs --session NAME"), std::string::npos) << r.err;
  r = runProcess({kObjdb, "db", "complete", "--db", db.string(), "--session", "monday", "--out",
                  out.string(), "--config", (dir / "missing.json").string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("cannot open config file"), std::string::npos) << r.err;
}

// The raw segments inserted again in creation order build what the store holds; a store that
// lost a model does not.
TEST(DbCommand, ReplaysTheRawSegmentsInCreationOrderAndComparesTheModels) {
  testing::TempDir dir;
  const fs::path db = dir / "objects.sqlite";
  ASSERT_NO_FATAL_FAILURE(writeTwoSessions(db));
  ProcessResult r = runProcess({kObjdb, "db", "replay", "--db", db.string()});
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  EXPECT_NE(r.out.find("replayed 2 segments"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("models: 1 stored, 1 replayed; merges: 1 stored, 1 replayed"),
            std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("the same"), std::string::npos) << r.out;
  {
    auto store = storage::SqliteStore::open(db.string()).value();
    ASSERT_TRUE(store->removeModel(store->modelIds().value().front()).ok());
  }
  r = runProcess({kObjdb, "db", "replay", "--db", db.string()});
  EXPECT_EQ(r.exit_code, 1) << r.out << r.err;
  EXPECT_NE(r.out.find("only in the replay: {monday/1, tuesday/1}"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("DIFFERENT"), std::string::npos) << r.out;

  const fs::path empty = dir / "empty.sqlite";
  ASSERT_TRUE(storage::SqliteStore::open(empty.string()).ok());
  r = runProcess({kObjdb, "db", "replay", "--db", empty.string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("holds no session: nothing to replay"), std::string::npos) << r.err;
}

TEST(DbCommand, BadArgumentsAndWrongFilesAreClearErrors) {
  testing::TempDir dir;
  ProcessResult r = runProcess({kObjdb, "db"});
  EXPECT_EQ(r.exit_code, 2);
  r = runProcess({kObjdb, "db", "vacuum", "--db", "x"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("unknown action"), std::string::npos) << r.err;
  r = runProcess({kObjdb, "db", "check"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("--db FILE is required"), std::string::npos) << r.err;
  r = runProcess({kObjdb, "db", "export", "--db", "x", "--model", "0", "--out", "y.ply"});
  EXPECT_EQ(r.exit_code, 2);
  r = runProcess({kObjdb, "db", "stats", "--db", (dir / "missing.sqlite").string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("no database at"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(dir / "missing.sqlite"));
  ASSERT_TRUE(testing::writeTextFile(dir / "notes.txt", std::string(3000, 'n')));
  r = runProcess({kObjdb, "db", "check", "--db", (dir / "notes.txt").string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("not a database"), std::string::npos) << r.err;
}

}  // namespace
}  // namespace objdb
