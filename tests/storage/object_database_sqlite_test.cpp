// The object database (Algorithm 1) over the SQLite store: the same result as in memory, and a
// reopened file carries on — the models, their segments and the scene maps are all there.
#include <gtest/gtest.h>

#include "core/database/object_database.h"
#include "storage/sqlite_store.h"
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

}  // namespace
}  // namespace objdb::storage
