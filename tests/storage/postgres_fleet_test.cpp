// Several servers on one PostgreSQL database, at the store and database level: the
// writer lock has one holder across stores (processes), the models' change sequence tells a
// store what the others changed, and an object database catches up on the models another
// server's database created, so that a segment of the same object merges into that model instead
// of becoming a second one.
#include "storage/postgres/postgres_store.h"

#include <atomic>
#include <chrono>
#include <memory>
#include <set>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "core/database/object_database.h"
#include "tests/storage/store_fixtures.h"
#include "tests/support/object_scenes.h"
#include "tests/support/postgres_test_cluster.h"

namespace objdb::storage {
namespace {

using objdb::testing::makeStoreModel;
using ::testing::ElementsAre;
using ::testing::IsEmpty;
using namespace std::chrono_literals;

// Two stores on one new database, as two servers would have.
struct TwoStores {
  std::unique_ptr<PostgresStore> a, b;
};
TwoStores twoStores(const std::string& hint) {
  const auto uri = objdb::testing::freshPostgresDatabase(hint);
  if (!uri.ok()) {
    ADD_FAILURE() << "no fresh test database: " << uri.status();
    return {};
  }
  auto a = PostgresStore::open(*uri);
  auto b = PostgresStore::open(*uri);
  if (!a.ok() || !b.ok()) {
    ADD_FAILURE() << a.status() << " / " << b.status();
    return {};
  }
  return {std::move(*a), std::move(*b)};
}

TEST(PostgresFleet, TheWriterLockHasOneHolderAcrossStores) {
  TwoStores s = twoStores("writer_lock");
  ASSERT_NE(s.a, nullptr);
  auto held = s.a->lockWriter();
  ASSERT_TRUE(held.ok()) << held.status();
  ASSERT_NE(*held, nullptr);
  std::atomic<bool> b_holds{false};
  std::thread other([&] {
    auto lock = s.b->lockWriter();
    ASSERT_TRUE(lock.ok()) << lock.status();
    b_holds = true;
  });
  std::this_thread::sleep_for(500ms);
  EXPECT_FALSE(b_holds) << "b took the writer lock while a held it";
  held->reset();  // a gives it up
  other.join();
  EXPECT_TRUE(b_holds);
  // Taken and given back again: the lock's connection stays usable.
  for (int k = 0; k < 3; ++k) {
    auto again = s.a->lockWriter();
    ASSERT_TRUE(again.ok()) << again.status();
  }
}

TEST(PostgresFleet, ChangesSinceListTheModelsOtherWritersChangedAndRetired) {
  TwoStores s = twoStores("model_changes");
  ASSERT_NE(s.a, nullptr);
  const int64_t start = s.b->modelChangeSeq().value();
  const int64_t kept = s.a->addModel(makeStoreModel(7, 2)).value();
  const int64_t gone = s.a->addModel(makeStoreModel(8, 1)).value();
  auto changes = s.b->modelChangesSince(start);
  ASSERT_TRUE(changes.ok()) << changes.status();
  EXPECT_GT(changes->seq, start);
  ASSERT_EQ(changes->entries.size(), 2u);
  EXPECT_EQ(changes->entries[0].id, kept);
  EXPECT_EQ(changes->entries[0].segments.size(), 2u);  // its observations' segment keys
  EXPECT_FALSE(changes->entries[0].descriptors.empty());
  EXPECT_THAT(changes->retired, IsEmpty());
  // Nothing changed since: nothing listed, the sequence stays.
  const auto none = s.b->modelChangesSince(changes->seq).value();
  EXPECT_EQ(none.seq, changes->seq);
  EXPECT_THAT(none.entries, IsEmpty());
  // A removal and a replacement: one retired, one changed, and only those.
  ASSERT_TRUE(s.a->removeModel(gone).ok());
  model::ObjectModel replaced = makeStoreModel(9, 3);
  replaced.id = kept;
  ASSERT_TRUE(s.a->replaceModel(std::move(replaced), std::nullopt).ok());
  const auto later = s.b->modelChangesSince(changes->seq).value();
  EXPECT_THAT(later.retired, ElementsAre(gone));
  ASSERT_EQ(later.entries.size(), 1u);
  EXPECT_EQ(later.entries[0].id, kept);
  EXPECT_EQ(later.entries[0].segments.size(), 3u);
  EXPECT_EQ(s.a->modelChangeSeq().value(), later.seq);
}

objdb::Params params() {
  objdb::Params p;
  p.tsdf.voxel_size_m = objdb::testing::kSceneVoxel;
  return p;
}

// The object of object_database_sqlite_test: Monday's front half, Tuesday's back half.
const objdb::testing::PlacedShape kMonday{objdb::testing::boxWithBall(),
                                          objdb::testing::poseXyYaw(0.3, -0.2, 0.3)};
const objdb::testing::PlacedShape kTuesday{objdb::testing::boxWithBall(),
                                           objdb::testing::poseXyYaw(-0.5, 0.4, 2.0)};

TEST(PostgresFleet, ADatabaseMergesIntoTheModelAnotherServersDatabaseCreated) {
  TwoStores s = twoStores("two_databases");
  ASSERT_NE(s.a, nullptr);
  ASSERT_TRUE(s.a->putScene("monday", std::make_shared<tsdf::TsdfLayer>(
                                          objdb::testing::sceneGrid({kMonday})))
                  .ok());
  ASSERT_TRUE(s.a->putScene("tuesday", std::make_shared<tsdf::TsdfLayer>(
                                           objdb::testing::sceneGrid({kTuesday})))
                  .ok());
  // Both databases start on the empty store, as two servers would.
  auto on_a = database::ObjectDatabase::create(params(), s.a.get()).value();
  auto on_b = database::ObjectDatabase::create(params(), s.b.get()).value();
  const auto monday =
      on_a->insertSegment("monday", objdb::testing::rawSegment(7, kMonday, {-0.3f, 0.1f}));
  ASSERT_TRUE(monday.ok()) << monday.status();
  EXPECT_FALSE(monday->merged);
  // B's database never saw A's model be made; it catches up before it matches.
  const auto tuesday =
      on_b->insertSegment("tuesday", objdb::testing::rawSegment(3, kTuesday, {-0.1f, 0.3f}));
  ASSERT_TRUE(tuesday.ok()) << tuesday.status();
  EXPECT_TRUE(tuesday->merged);
  EXPECT_EQ(tuesday->model_id, monday->model_id);
  EXPECT_EQ(s.a->modelIds().value().size(), 1u);
  // And A's database knows that B's merge holds Tuesday's segment: withdrawing it from A's
  // rebuilds the model with Monday's alone.
  EXPECT_EQ(on_a->withdrawSegment("tuesday", 3).value().model_id, monday->model_id);
  EXPECT_EQ(s.b->model(monday->model_id).value()->observations.size(), 1u);
  // A re-extraction on B of Monday's segment replaces A's contribution, no second model.
  const auto again =
      on_b->insertSegment("monday", objdb::testing::rawSegment(7, kMonday, {-0.3f, 0.1f}));
  ASSERT_TRUE(again.ok()) << again.status();
  EXPECT_TRUE(again->replaced_earlier);
  EXPECT_EQ(s.a->modelIds().value().size(), 1u);
}

// The models of a store as the segments each holds, in no particular order.
std::set<std::set<std::pair<std::string, uint32_t>>> holdings(const database::ModelStore& store) {
  std::set<std::set<std::pair<std::string, uint32_t>>> out;
  const std::vector<int64_t> ids = store.modelIds().value();
  for (const int64_t id : ids) {
    std::set<std::pair<std::string, uint32_t>> held;
    const std::shared_ptr<const model::ObjectModel> m = store.model(id).value();
    for (const auto& o : m->observations) held.insert({o.session, o.label});
    out.insert(held);
  }
  return out;
}

// What "the same result" means with several servers: inserts and withdrawals interleaved across
// two databases on two stores end as one database would end with the same operations in the
// order they took the writer lock (here: the order they ran): the same models, holding the same
// segments, after the same number of merges.
TEST(PostgresFleet, InterleavedWritersEndAsOneWriterInTheirLockOrder) {
  TwoStores s = twoStores("interleaved");
  ASSERT_NE(s.a, nullptr);
  const objdb::testing::PlacedShape wednesday{objdb::testing::boxWithBall(),
                                              objdb::testing::poseXyYaw(1.0, 1.0, -1.0)};
  database::InMemoryModelStore reference_store;
  for (database::ModelStore* store : {static_cast<database::ModelStore*>(s.a.get()),
                                      static_cast<database::ModelStore*>(&reference_store)}) {
    for (const auto& [name, shape] :
         {std::pair{"monday", kMonday}, {"tuesday", kTuesday}, {"wednesday", wednesday}}) {
      ASSERT_TRUE(store->putScene(name, std::make_shared<tsdf::TsdfLayer>(
                                            objdb::testing::sceneGrid({shape})))
                      .ok());
    }
  }
  auto on_a = database::ObjectDatabase::create(params(), s.a.get()).value();
  auto on_b = database::ObjectDatabase::create(params(), s.b.get()).value();
  auto reference = database::ObjectDatabase::create(params(), &reference_store).value();
  struct Step {
    database::ObjectDatabase* fleet;  // which server's database runs it
    std::string session;
    uint32_t label;
    objdb::testing::PlacedShape shape;
    objdb::testing::View view;
    bool withdraw;
  };
  const std::vector<Step> steps = {
      {on_a.get(), "monday", 7, kMonday, {-0.3f, 0.1f}, false},
      {on_b.get(), "tuesday", 3, kTuesday, {-0.1f, 0.3f}, false},
      {on_a.get(), "wednesday", 5, wednesday, {}, false},
      {on_a.get(), "tuesday", 3, kTuesday, {-0.1f, 0.3f}, false},  // re-extracted
      {on_b.get(), "monday", 7, kMonday, {}, true},                // withdrawn
      {on_b.get(), "monday", 8, kMonday, {-0.3f, 0.3f}, false},
  };
  size_t merges = 0;
  for (const Step& step : steps) {
    SCOPED_TRACE(step.session + "/" + std::to_string(step.label));
    for (database::ObjectDatabase* db : {step.fleet, reference.get()}) {
      if (step.withdraw) {
        ASSERT_TRUE(db->withdrawSegment(step.session, step.label).ok());
        continue;
      }
      const auto report = db->insertSegment(
          step.session, objdb::testing::rawSegment(step.label, step.shape, step.view));
      ASSERT_TRUE(report.ok()) << report.status();
      if (db == step.fleet) merges += report->merged ? 1 : 0;
    }
    EXPECT_EQ(holdings(*s.b), holdings(reference_store));
  }
  EXPECT_GT(merges, 0u);  // the servers' databases merged into each other's models
  EXPECT_EQ(s.a->mergeRecords().value().size(), reference_store.mergeRecords().value().size());
}

}  // namespace
}  // namespace objdb::storage
