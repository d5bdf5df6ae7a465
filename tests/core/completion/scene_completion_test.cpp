#include "core/completion/scene_completion.h"

#include <cmath>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "core/database/object_database.h"
#include "tests/support/object_scenes.h"

namespace objdb::completion {
namespace {

using objdb::testing::boxWithBall;
using objdb::testing::kSceneVoxel;
using objdb::testing::PlacedShape;
using objdb::testing::poseXyYaw;
using objdb::testing::rawSegment;
using objdb::testing::sceneGrid;
using objdb::testing::View;
using ::testing::HasSubstr;

// The same object seen from its front end on Monday and from its back end on Tuesday.
const PlacedShape kMonday{boxWithBall(), poseXyYaw(0.3, -0.2, 0.3)};
const PlacedShape kTuesday{boxWithBall(), poseXyYaw(-0.5, 0.4, 2.0)};
const View kFront{-1.0f, 0.12f}, kBack{-0.12f, 1.0f};

Params params() {
  Params p;
  p.tsdf.voxel_size_m = kSceneVoxel;
  return p;
}

struct Fixture {
  database::InMemoryModelStore store;
  std::unique_ptr<database::ObjectDatabase> db;
  Fixture() {
    EXPECT_TRUE(store.putScene("monday", std::make_shared<tsdf::TsdfLayer>(sceneGrid({kMonday}, {kFront}))).ok());
    EXPECT_TRUE(store.putScene("tuesday", std::make_shared<tsdf::TsdfLayer>(sceneGrid({kTuesday}, {kBack}))).ok());
    db = database::ObjectDatabase::create(params(), &store).value();
  }
};

TEST(CompleteScene, FillsTheSideOfAnObjectThatOnlyAnotherSessionSaw) {
  Fixture f;
  ASSERT_TRUE(f.db->insertSegment("monday", rawSegment(1, kMonday, kFront)).ok());
  auto merged = f.db->insertSegment("tuesday", rawSegment(1, kTuesday, kBack));
  ASSERT_TRUE(merged.ok()) << merged.status();
  ASSERT_TRUE(merged->merged) << (merged->results.empty() ? "no candidate"
                                                          : merged->results[0].reason);
  // A point on the object's back face (object-frame x = 0.2), which Monday never observed.
  const Eigen::Vector3f back_object(0.2f, 0.0f, 0.1f);
  const Eigen::Vector3f back_world = kMonday.T_world_object.cast<float>() * back_object;
  float d = 0.0f;
  const auto scene = f.store.scene("monday").value();
  ASSERT_FALSE(scene->interpolateDistance(back_world, &d));

  CompletionReport report;
  auto completed = completeScene(f.store, "monday", params().merging, params().tsdf, &report);
  ASSERT_TRUE(completed.ok()) << completed.status();
  ASSERT_EQ(report.placements.size(), 1u);
  const Placement& p = report.placements[0];
  EXPECT_TRUE(p.verified) << p.verdict.reason;
  EXPECT_EQ(p.model_segments, 2u);
  EXPECT_GT(p.filled_surface_voxels, 100u);
  EXPECT_EQ(report.filled_voxels, p.filled_voxels);
  // The back face is there now, where the true surface is (registration error aside).
  ASSERT_TRUE(completed->interpolateDistance(back_world, &d));
  EXPECT_LT(std::abs(d), 0.015f);
  // What Monday measured is untouched.
  const Eigen::Vector3f front_world =
      kMonday.T_world_object.cast<float>() * Eigen::Vector3f(-0.2f, 0.0f, 0.1f);
  float before = 0.0f, after = 0.0f;
  ASSERT_TRUE(scene->interpolateDistance(front_world, &before));
  ASSERT_TRUE(completed->interpolateDistance(front_world, &after));
  EXPECT_EQ(before, after);

  // Asked to stop, it stops before the model and says how far it got.
  size_t asked = 0;
  auto stopped = completeScene(f.store, "monday", params().merging, params().tsdf, &report, [&] {
    ++asked;
    return true;
  });
  ASSERT_FALSE(stopped.ok());
  EXPECT_EQ(stopped.status().code(), absl::StatusCode::kCancelled);
  EXPECT_THAT(std::string(stopped.status().message()), HasSubstr("after 0 of 1 models"));
  EXPECT_EQ(asked, 1u);
}

// A segment's grid also holds the band of whatever stood near the object (here a plate beside it
// on Tuesday, not in the segment's label voxels). Completion pastes the object, not its
// neighbourhood: Monday gets the back face but no plate.
TEST(CompleteScene, FillsTheObjectButNotWhatStoodNearItInAnotherSession) {
  Fixture f;
  ASSERT_TRUE(f.db->insertSegment("monday", rawSegment(1, kMonday, kFront)).ok());
  gsm::RawSegment tuesday = rawSegment(1, kTuesday, kBack);
  // A vertical plate at object-frame y = 0.3 (the shape reaches y = 0.15), x and z in [0, 0.12]: its
  // band of ±3 voxels, written into the segment's grid (segment frame = world frame here).
  const float voxel = tuesday.grid.voxelSize();
  const Eigen::Isometry3f T_object_world = kTuesday.T_world_object.inverse().cast<float>();
  auto plate_distance = [](const Eigen::Vector3f& p) { return p.y() - 0.3f; };
  for (float x = 0.0f; x <= 0.12f; x += voxel / 2) {
    for (float z = 0.0f; z <= 0.12f; z += voxel / 2) {
      for (float y = 0.3f - 3 * voxel; y <= 0.3f + 3 * voxel; y += voxel / 2) {
        const Eigen::Vector3f world = kTuesday.T_world_object.cast<float>() * Eigen::Vector3f(x, y, z);
        const tsdf::VoxelIndex v = tuesday.grid.voxelIndexOf(world);
        tuesday.grid.allocateBlock(tuesday.grid.blockOfVoxel(v));
        tsdf::TsdfVoxel* voxel_ptr = tuesday.grid.voxel(v);
        voxel_ptr->distance = plate_distance(T_object_world * tuesday.grid.voxelCenter(v));
        voxel_ptr->weight = 5.0f;
      }
    }
  }
  auto merged = f.db->insertSegment("tuesday", tuesday);
  ASSERT_TRUE(merged.ok()) << merged.status();
  ASSERT_TRUE(merged->merged) << (merged->results.empty() ? "no candidate"
                                                          : merged->results[0].reason);
  const Eigen::Vector3f plate_world =
      kMonday.T_world_object.cast<float>() * Eigen::Vector3f(0.06f, 0.3f, 0.06f);
  const Eigen::Vector3f back_world =
      kMonday.T_world_object.cast<float>() * Eigen::Vector3f(0.2f, 0.0f, 0.1f);
  float d = 0.0f;
  ASSERT_FALSE(f.store.scene("monday").value()->interpolateDistance(plate_world, &d));

  Params p = params();
  CompletionReport report;
  auto completed = completeScene(f.store, "monday", p.merging, p.tsdf, &report);
  ASSERT_TRUE(completed.ok()) << completed.status();
  ASSERT_EQ(report.placements.size(), 1u);
  EXPECT_TRUE(completed->interpolateDistance(back_world, &d));
  EXPECT_FALSE(completed->interpolateDistance(plate_world, &d)) << "the plate was pasted: " << d;
  // The largest margin (4 voxels, 8 cm) does not reach it either.
  p.merging.completion_margin_voxels = 4;
  auto widest = completeScene(f.store, "monday", p.merging, p.tsdf, nullptr);
  ASSERT_TRUE(widest.ok());
  EXPECT_FALSE(widest->interpolateDistance(plate_world, &d));
  // The model's whole grid, filled at the same placement, brings the plate along: the region is
  // what keeps it out.
  const auto model = f.store.model(report.placements[0].model_id).value();
  tsdf::TsdfLayer whole = f.store.scene("monday").value()->clone();
  matching::MergeOptions fill;
  fill.mode = matching::MergeMode::kFillUnobserved;
  matching::mergeGrids(&whole, model->grid, report.placements[0].T_world_object, 1000.0f, fill);
  EXPECT_TRUE(whole.interpolateDistance(plate_world, &d));
}

TEST(CompleteScene, AModelMergedBeyondThePapersETsdfFillsNothing) {
  Fixture f;
  ASSERT_TRUE(f.db->insertSegment("monday", rawSegment(1, kMonday, kFront)).ok());
  auto merged = f.db->insertSegment("tuesday", rawSegment(1, kTuesday, kBack));
  ASSERT_TRUE(merged.ok() && merged->merged);
  const auto records = f.store.mergeRecords().value();
  ASSERT_EQ(records.size(), 1u);
  ASSERT_GT(records[0].tsdf_rmse_m, 0.0);
  // As if that merge had needed a session's depth noise: e*_TSDF below its e_TSDF.
  Params p = params();
  p.merging.tsdf_max_rmse_m = float(records[0].tsdf_rmse_m * 0.99);
  CompletionReport report;
  auto completed = completeScene(f.store, "monday", p.merging, p.tsdf, &report);
  ASSERT_TRUE(completed.ok()) << completed.status();
  ASSERT_EQ(report.placements.size(), 1u);
  EXPECT_TRUE(report.placements[0].blurred);
  EXPECT_EQ(report.placements[0].filled_voxels, 0u);
  EXPECT_EQ(report.filled_voxels, 0u);
  // Within the threshold it fills (the test above).
  CompletionReport plain;
  ASSERT_TRUE(completeScene(f.store, "monday", params().merging, params().tsdf, &plain).ok());
  EXPECT_FALSE(plain.placements[0].blurred);
  EXPECT_GT(plain.filled_voxels, 0u);
}

TEST(CompleteScene, SingleSegmentModelsAddNothingAndAMissingSceneIsAnError) {
  Fixture f;
  ASSERT_TRUE(f.db->insertSegment("monday", rawSegment(1, kMonday, kFront)).ok());
  CompletionReport report;
  auto completed = completeScene(f.store, "monday", params().merging, params().tsdf, &report);
  ASSERT_TRUE(completed.ok());
  EXPECT_TRUE(report.placements.empty());
  EXPECT_EQ(completed->numObservedVoxels(), f.store.scene("monday").value()->numObservedVoxels());
  const auto missing = completeScene(f.store, "friday", params().merging, params().tsdf, nullptr);
  EXPECT_EQ(missing.status().code(), absl::StatusCode::kNotFound);
  EXPECT_THAT(std::string(missing.status().message()), HasSubstr("session friday"));
}

}  // namespace
}  // namespace objdb::completion
