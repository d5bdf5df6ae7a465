// A merge extends the stored model by the new segment alone (ObjectDatabase::extendModel): the
// model must be the one its every raw segment, fused again in order, would make.
#include <gtest/gtest.h>

#include "core/database/object_database.h"
#include "tests/support/model_compare.h"
#include "tests/support/object_scenes.h"

namespace objdb::database {
namespace {

using objdb::testing::boxWithBall;
using objdb::testing::sceneGrid;
using objdb::testing::View;
using World = objdb::testing::PlacedShape;

Params params() {
  Params p;
  p.tsdf.voxel_size_m = objdb::testing::kSceneVoxel;
  return p;
}

// One object on four days, each time elsewhere, turned, and seen from another side.
struct Day {
  const char* session;
  World world;
  View view;
  float depth_m;  // the depth it was seen from (0: unknown)
};
const Day kDays[] = {
    {"monday", {boxWithBall(), objdb::testing::poseXyYaw(0.3, -0.2, 0.3)}, {-0.3f, 0.1f}, 1.2f},
    {"tuesday", {boxWithBall(), objdb::testing::poseXyYaw(-0.5, 0.4, 2.0)}, {-0.1f, 0.3f}, 0.0f},
    {"wednesday", {boxWithBall(), objdb::testing::poseXyYaw(0.1, 0.6, -1.0)}, {-0.2f, 0.2f}, 2.1f},
    {"thursday",
     {boxWithBall(), objdb::testing::poseXyYaw(-0.2, -0.4, 1.2)},
     {-0.25f, 0.25f},
     1.6f},
};

TEST(ObjectDatabaseBuild,
     AMergeFusesTheNewSegmentIntoTheStoredModelAndMakesTheModelOfAllItsSegments) {
  InMemoryModelStore store;
  const Params p = params();
  auto db = ObjectDatabase::create(p, &store).value();
  std::vector<size_t> fused;
  int64_t id = 0;
  for (const Day& day : kDays) {
    ASSERT_TRUE(
        store.putScene(day.session, std::make_shared<tsdf::TsdfLayer>(sceneGrid({day.world})))
            .ok());
    gsm::RawSegment segment = objdb::testing::rawSegment(5, day.world, day.view);
    segment.observation_depth_m = day.depth_m;
    const auto report = db->insertSegment(day.session, segment);
    ASSERT_TRUE(report.ok()) << report.status();
    if (id == 0) {
      id = report->model_id;
      continue;
    }
    ASSERT_TRUE(report->merged) << day.session;
    ASSERT_EQ(report->model_id, id);
    fused.push_back(report->merge_fused_segments);
  }
  // A model of one segment is rebuilt from both (its grid is the segment's as extracted); a model
  // of several takes the new segment alone.
  EXPECT_EQ(fused, (std::vector<size_t>{2, 1, 1}));
  const auto stored = store.model(id).value();
  ASSERT_EQ(stored->observations.size(), 4u);
  const auto reference = objdb::testing::rebuiltFromSegments(store, *stored, p);
  ASSERT_TRUE(reference.ok()) << reference.status();
  EXPECT_EQ(objdb::testing::diffModels(*stored, *reference, false), "");
  EXPECT_GT(stored->descriptors.size(), 3u);
}

// The reference itself tells models apart: the same segments fused in another order, or with a
// lower weight cap, make another grid.
TEST(ObjectDatabaseBuild, TheReferenceSeesAnotherFusion) {
  InMemoryModelStore store;
  Params p = params();
  auto db = ObjectDatabase::create(p, &store).value();
  int64_t id = 0;
  for (const Day& day : kDays) {
    ASSERT_TRUE(
        store.putScene(day.session, std::make_shared<tsdf::TsdfLayer>(sceneGrid({day.world})))
            .ok());
    const auto report =
        db->insertSegment(day.session, objdb::testing::rawSegment(5, day.world, day.view));
    ASSERT_TRUE(report.ok()) << report.status();
    if (id == 0) id = report->model_id;
  }
  const auto stored = store.model(id).value();
  ASSERT_EQ(stored->observations.size(), 4u);
  model::ObjectModel reordered = model::cloneModel(*stored);
  std::swap(reordered.observations[2], reordered.observations[3]);
  const auto other_order = objdb::testing::rebuiltFromSegments(store, reordered, p).value();
  EXPECT_NE(objdb::testing::diffLayers(stored->grid, other_order.grid), "");
  p.tsdf.max_weight = 5.0f;
  const auto capped = objdb::testing::rebuiltFromSegments(store, *stored, p).value();
  EXPECT_NE(objdb::testing::diffModels(*stored, capped, false), "");
}

}  // namespace
}  // namespace objdb::database
