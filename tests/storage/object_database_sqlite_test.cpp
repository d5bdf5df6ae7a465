// The object database (Algorithm 1) over the SQLite store: the same result as in memory, and a
// reopened file carries on — the models, their segments and the scene maps are all there.
#include <sqlite3.h>

#include <tuple>

#include <gtest/gtest.h>

#include "core/database/object_database.h"
#include "storage/sqlite/sqlite_store.h"
#include "tests/support/faulty_vfs.h"
#include "tests/support/model_compare.h"
#include "tests/support/object_scenes.h"
#include "tests/support/temp_dir.h"

namespace objdb::storage {
namespace {

using objdb::testing::boxWithBall;
using objdb::testing::kSceneVoxel;
using objdb::testing::sceneGrid;
using objdb::testing::View;
using World = objdb::testing::PlacedShape;

const World kMonday{boxWithBall(), objdb::testing::poseXyYaw(0.3, -0.2, 0.3)};
const World kTuesday{boxWithBall(), objdb::testing::poseXyYaw(-0.5, 0.4, 2.0)};

objdb::Params params() {
  objdb::Params p;
  p.tsdf.voxel_size_m = kSceneVoxel;
  return p;
}

// Inserts Monday's front half and Tuesday's back half of the same object.
void insertBoth(database::ModelStore* store) {
  ASSERT_TRUE(store->putScene("monday", std::make_shared<tsdf::TsdfLayer>(sceneGrid({kMonday}))).ok());
  ASSERT_TRUE(store->putScene("tuesday", std::make_shared<tsdf::TsdfLayer>(sceneGrid({kTuesday}))).ok());
  auto db = database::ObjectDatabase::create(params(), store).value();
  ASSERT_TRUE(db->insertSegment("monday", objdb::testing::rawSegment(7, kMonday, View{-0.3f, 0.1f})).ok());
  const auto second =
      db->insertSegment("tuesday", objdb::testing::rawSegment(3, kTuesday, View{-0.1f, 0.3f}));
  ASSERT_TRUE(second.ok()) << second.status();
  EXPECT_TRUE(second->merged);
}

TEST(ObjectDatabaseOnSqlite, MatchesInMemoryAndCarriesOnAfterReopen) {
  database::InMemoryModelStore memory;
  insertBoth(&memory);
  objdb::testing::TempDir dir;
  const std::string path = (dir / "db.sqlite").string();
  {
    auto store = SqliteStore::open(path).value();
    insertBoth(store.get());
  }
  auto store = SqliteStore::open(path).value();
  ASSERT_EQ(store->modelIds().value().size(), 1u);
  ASSERT_EQ(memory.modelIds().value().size(), 1u);
  const auto stored = store->model(1).value();
  const auto expected = memory.model(1).value();
  ASSERT_EQ(stored->observations.size(), 2u);
  EXPECT_TRUE(stored->observations[1].T_world_object.isApprox(expected->observations[1].T_world_object, 1e-9));
  EXPECT_EQ(stored->cloud.points, expected->cloud.points);
  EXPECT_EQ(store->mergeRecords().value().size(), 1u);

  // A new database over the reopened file knows which model holds Tuesday's segment: its
  // re-extraction replaces the contribution instead of adding a second copy.
  auto db = database::ObjectDatabase::create(params(), store.get()).value();
  const auto again =
      db->insertSegment("tuesday", objdb::testing::rawSegment(3, kTuesday, View{-0.1f, 0.3f}));
  ASSERT_TRUE(again.ok()) << again.status();
  EXPECT_TRUE(again->replaced_earlier);
  EXPECT_TRUE(again->merged);
  EXPECT_EQ(store->modelIds().value().size(), 1u);
  EXPECT_EQ(store->model(1).value()->observations.size(), 2u);
}

// A merge into a model of several segments fuses the new one into the model's grid as the file
// stored it: after the round trip through the file, the merged model is still the one all its
// segments, read back and fused again in order, make (tests/support/model_compare.h).
TEST(ObjectDatabaseOnSqlite, AMergedModelIsTheModelOfAllItsStoredSegments) {
  const World wednesday{boxWithBall(), objdb::testing::poseXyYaw(0.1, 0.6, -1.0)};
  objdb::testing::TempDir dir;
  auto store = SqliteStore::open((dir / "db.sqlite").string()).value();
  insertBoth(store.get());
  ASSERT_TRUE(
      store->putScene("wednesday", std::make_shared<tsdf::TsdfLayer>(sceneGrid({wednesday}))).ok());
  // A database over the file: the model of two segments comes from the store, not from memory.
  auto db = database::ObjectDatabase::create(params(), store.get()).value();
  auto segment = objdb::testing::rawSegment(2, wednesday, View{-0.2f, 0.2f});
  segment.observation_depth_m = 1.7f;
  const auto third = db->insertSegment("wednesday", segment);
  ASSERT_TRUE(third.ok()) << third.status();
  ASSERT_TRUE(third->merged);
  EXPECT_EQ(third->merge_fused_segments, 1u);
  const auto stored = store->model(third->model_id).value();
  ASSERT_EQ(stored->observations.size(), 3u);
  const auto reference = objdb::testing::rebuiltFromSegments(*store, *stored, params());
  ASSERT_TRUE(reference.ok()) << reference.status();
  EXPECT_EQ(objdb::testing::diffModels(*stored, *reference, false), "");
}

// A lone segment extracted again after it changed: its first model is emptied and removed, and the
// tombstone names the model that holds the segment now.
TEST(ObjectDatabaseOnSqlite, ARemovedModelsTombstoneNamesWhereItsSegmentWent) {
  objdb::testing::TempDir dir;
  auto store = SqliteStore::open((dir / "db.sqlite").string()).value();
  ASSERT_TRUE(store->putScene("monday", std::make_shared<tsdf::TsdfLayer>(sceneGrid({kMonday}))).ok());
  auto db = database::ObjectDatabase::create(params(), store.get()).value();
  const auto first =
      db->insertSegment("monday", objdb::testing::rawSegment(7, kMonday, View{-0.3f, 0.1f}));
  ASSERT_TRUE(first.ok()) << first.status();
  const auto again =
      db->insertSegment("monday", objdb::testing::rawSegment(7, kMonday, View{-0.3f, 0.2f}));
  ASSERT_TRUE(again.ok()) << again.status();
  ASSERT_EQ(again->removed_model, first->model_id);
  ASSERT_NE(again->model_id, first->model_id);
  const ModelFate fate = store->modelFate(first->model_id).value();
  EXPECT_EQ(fate.state, "removed");
  EXPECT_EQ(fate.next, again->model_id);
  EXPECT_EQ(store->modelFate(again->model_id).value().state, "active");
}

// I/O errors at the database level: Tuesday's insert, which merges into Monday's model,
// meets a store whose k-th write, sync or truncate fails and keeps failing. It reports the error;
// retried once the fault is lifted, it ends as an insert that never failed (one model holding
// both segments, one merge record), and the file passes its checks.
TEST(ObjectDatabaseOnSqlite, AnInsertThatFailsOnDiskEndsAsIfItNeverFailedWhenRetried) {
  objdb::testing::FaultyVfs vfs;
  const auto tuesday = [] { return objdb::testing::rawSegment(3, kTuesday, View{-0.1f, 0.3f}); };
  const auto prepare = [&](const std::string& path, std::unique_ptr<SqliteStore>* store,
                           std::unique_ptr<database::ObjectDatabase>* db) {
    *store = SqliteStore::open(path).value();
    ASSERT_TRUE((*store)->putScene("monday", std::make_shared<tsdf::TsdfLayer>(sceneGrid({kMonday}))).ok());
    ASSERT_TRUE((*store)->putScene("tuesday", std::make_shared<tsdf::TsdfLayer>(sceneGrid({kTuesday}))).ok());
    *db = database::ObjectDatabase::create(params(), store->get()).value();
    ASSERT_TRUE((*db)->insertSegment("monday", objdb::testing::rawSegment(7, kMonday, View{-0.3f, 0.1f})).ok());
  };
  const auto expectMerged = [](const SqliteStore& store) {
    const auto report = store.check();
    ASSERT_TRUE(report.ok()) << report.status();
    EXPECT_TRUE(report->ok());
    ASSERT_EQ(store.modelIds().value(), std::vector<int64_t>{1});
    EXPECT_EQ(store.model(1).value()->observations.size(), 2u);
    EXPECT_EQ(store.mergeRecords().value().size(), 1u);
  };

  int64_t operations = 0;
  {
    objdb::testing::TempDir dir;
    std::unique_ptr<SqliteStore> store;
    std::unique_ptr<database::ObjectDatabase> db;
    ASSERT_NO_FATAL_FAILURE(prepare((dir / "db.sqlite").string(), &store, &db));
    vfs.failAt(0, false);
    const auto second = db->insertSegment("tuesday", tuesday());
    operations = vfs.operations();
    vfs.lift();
    ASSERT_TRUE(second.ok()) << second.status();
    ASSERT_TRUE(second->merged);
  }
  ASSERT_GE(operations, 6) << "the insert stores the raw segment, then the merged model";

  int failed = 0, failed_in_merge = 0;
  const int64_t step = std::max<int64_t>(1, operations / 10);
  for (int64_t k = 1; k <= operations; k += step) {
    SCOPED_TRACE(::testing::Message() << "operation " << k << " of " << operations);
    objdb::testing::TempDir dir;
    const std::string path = (dir / "db.sqlite").string();
    std::unique_ptr<SqliteStore> store;
    std::unique_ptr<database::ObjectDatabase> db;
    ASSERT_NO_FATAL_FAILURE(prepare(path, &store, &db));
    vfs.failAt(k, /*persistent=*/true);
    auto second = db->insertSegment("tuesday", tuesday());
    vfs.lift();
    if (!second.ok()) {
      ++failed;
      EXPECT_EQ(second.status().code(), absl::StatusCode::kUnavailable) << second.status();
      // The raw segment was stored and the merged model was not.
      if (second.status().message().find("replacing object model") != absl::string_view::npos) {
        ++failed_in_merge;
      }
      second = db->insertSegment("tuesday", tuesday());
      ASSERT_TRUE(second.ok()) << second.status();
      // The failed insert left nothing of Tuesday's segment in any model to replace.
      EXPECT_FALSE(second->replaced_earlier);
    }
    EXPECT_TRUE(second->merged);
    expectMerged(*store);
    // A database over the reopened file agrees: re-extracting Tuesday's segment replaces it.
    db.reset();
    store.reset();
    store = SqliteStore::open(path).value();
    expectMerged(*store);
    db = database::ObjectDatabase::create(params(), store.get()).value();
    const auto again = db->insertSegment("tuesday", tuesday());
    ASSERT_TRUE(again.ok()) << again.status();
    EXPECT_TRUE(again->replaced_earlier);
    EXPECT_EQ(store->modelIds().value(), std::vector<int64_t>{1});
    EXPECT_EQ(store->model(1).value()->observations.size(), 2u);
  }
  EXPECT_GE(failed, 5);
  EXPECT_GE(failed_in_merge, 1) << "no sampled fault hit the merge itself";
}

// The global index (two-stage retrieval) is the store's global_descriptor column: a database
// reopened on the file ranks as the one that inserted; a file whose column was emptied (a store
// of an older schema) gets it rebuilt from the local descriptors, ranks the same, and keeps it.
TEST(ObjectDatabaseOnSqlite, TheGlobalIndexSurvivesARestartAndEqualsARebuild) {
  using objdb::testing::chair;
  using objdb::testing::extinguisher;
  const World chair_a{chair(), objdb::testing::poseXyYaw(0, 0, 0.2)};
  const World fire{extinguisher(), objdb::testing::poseXyYaw(1.0, 0.5, 1.0)};
  const World box{boxWithBall(), objdb::testing::poseXyYaw(-1.0, 0.8, 0.7)};
  const World chair_b{chair(), objdb::testing::poseXyYaw(0.2, -1.2, 1.9)};
  objdb::Params p = params();
  p.database.shortlist = 1;
  objdb::testing::TempDir dir;
  // The rankings a fourth segment (the second chair) meets, after a reopen.
  auto rankAfterReopen = [&](const std::string& path, bool empty_the_column) {
    {
      auto store = SqliteStore::open(path).value();
      EXPECT_TRUE(store->putScene("s", std::make_shared<tsdf::TsdfLayer>(
                                           sceneGrid({chair_a, fire, box, chair_b})))
                      .ok());
      auto db = database::ObjectDatabase::create(p, store.get()).value();
      uint32_t label = 1;
      for (const World* w : {&chair_a, &fire, &box}) {
        EXPECT_TRUE(db->insertSegment("s", objdb::testing::rawSegment(label++, *w)).ok());
      }
    }
    if (empty_the_column) {
      sqlite3* raw = nullptr;
      EXPECT_EQ(sqlite3_open(path.c_str(), &raw), SQLITE_OK);
      EXPECT_EQ(sqlite3_exec(raw, "UPDATE models SET global_descriptor = NULL", nullptr, nullptr,
                             nullptr),
                SQLITE_OK);
      sqlite3_close(raw);
    }
    auto store = SqliteStore::open(path).value();
    auto db = database::ObjectDatabase::create(p, store.get()).value();
    db->measurePrefilterRecall(true);
    const auto r = db->insertSegment("s", objdb::testing::rawSegment(4, chair_b, View{-10, 0.05f}));
    EXPECT_TRUE(r.ok()) << r.status();
    size_t stored = 0;
    for (const auto& e : store->matchEntries(false).value().entries) stored += !e.global.empty();
    return std::make_tuple(r->global_ranking, r->shortlist, r->model_id, stored);
  };
  const auto [kept, kept_list, kept_model, kept_stored] =
      rankAfterReopen((dir / "kept.sqlite").string(), false);
  const auto [rebuilt, rebuilt_list, rebuilt_model, rebuilt_stored] =
      rankAfterReopen((dir / "rebuilt.sqlite").string(), true);
  ASSERT_EQ(kept.size(), 3u);
  EXPECT_EQ(kept_list, std::vector<int64_t>{1});  // the first chair heads the list
  EXPECT_EQ(kept_model, 1);                      // and takes the second
  EXPECT_EQ(rebuilt, kept);
  EXPECT_EQ(rebuilt_list, kept_list);
  EXPECT_EQ(rebuilt_model, kept_model);
  EXPECT_EQ(kept_stored, 3u);
  EXPECT_EQ(rebuilt_stored, 3u);  // written back when the database opened
}

}  // namespace
}  // namespace objdb::storage
