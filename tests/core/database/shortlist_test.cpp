// Two-stage retrieval (DatabaseParams::shortlist): the global descriptors pick the models the
// descriptor vote runs over; the analytic shapes of tests/support/object_scenes.h.
#include <algorithm>

#include <gtest/gtest.h>

#include "core/database/object_database.h"
#include "tests/support/object_scenes.h"

namespace objdb::database {
namespace {

using objdb::testing::boxWithBall;
using objdb::testing::chair;
using objdb::testing::extinguisher;
using objdb::testing::kSceneVoxel;
using objdb::testing::sceneGrid;
using objdb::testing::View;
using World = objdb::testing::PlacedShape;

Params params(int shortlist) {
  Params p;
  p.tsdf.voxel_size_m = kSceneVoxel;
  p.database.threads = 2;
  p.database.shortlist = shortlist;
  return p;
}

const World kChair{chair(), objdb::testing::poseXyYaw(0, 0, 0.2)};
const World kExtinguisher{extinguisher(), objdb::testing::poseXyYaw(1.0, 0.5, 1.0)};
const World kBox{boxWithBall(), objdb::testing::poseXyYaw(-1.0, 0.8, 0.7)};
const World kChairAgain{chair(), objdb::testing::poseXyYaw(0.2, -1.2, 1.9)};

struct Fixture {
  InMemoryModelStore store;
  std::unique_ptr<ObjectDatabase> db;
  int64_t chair_id = 0, extinguisher_id = 0, box_id = 0;
  explicit Fixture(int shortlist) {
    db = ObjectDatabase::create(params(shortlist), &store).value();
    EXPECT_TRUE(store
                    .putScene("s", std::make_shared<tsdf::TsdfLayer>(
                                       sceneGrid({kChair, kExtinguisher, kBox, kChairAgain})))
                    .ok());
    chair_id = insert(1, kChair).model_id;
    extinguisher_id = insert(2, kExtinguisher).model_id;
    box_id = insert(3, kBox).model_id;
    db->measurePrefilterRecall(true);
  }
  InsertReport insert(uint32_t label, const World& w, View view = {}) {
    auto r = db->insertSegment("s", objdb::testing::rawSegment(label, w, view));
    EXPECT_TRUE(r.ok()) << r.status();
    return r.ok() ? *r : InsertReport{};
  }
};

TEST(Shortlist, HoldsTheModelTheFullVoteFindsAndTheSegmentMergesIntoIt) {
  Fixture f(1);  // one model of three: the vote runs over the chair alone
  ASSERT_NE(f.chair_id, 0);
  // Half of the second chair, seen from one side, at another place and turn.
  const InsertReport r = f.insert(4, kChairAgain, View{-10.0f, 0.05f});
  EXPECT_EQ(r.shortlist, std::vector<int64_t>{f.chair_id});
  ASSERT_EQ(r.global_ranking.size(), 3u);
  EXPECT_EQ(r.global_ranking.front(), f.chair_id);
  ASSERT_FALSE(r.exhaustive_candidates.empty());
  EXPECT_EQ(r.exhaustive_candidates.front(), f.chair_id);
  EXPECT_EQ(r.prefilter_candidates, std::vector<int64_t>{f.chair_id});
  EXPECT_TRUE(r.merged);
  EXPECT_EQ(r.model_id, f.chair_id);
}

TEST(Shortlist, AListAsLongAsTheDatabaseVotesAsTheFullSearchDoes) {
  Fixture f(3);
  const InsertReport r = f.insert(4, kChairAgain);
  EXPECT_EQ(r.shortlist, r.global_ranking);
  EXPECT_EQ(r.shortlist.size(), 3u);
  EXPECT_EQ(r.prefilter_candidates, r.exhaustive_candidates);
  EXPECT_TRUE(r.merged);
}

TEST(Shortlist, WithoutAListTheVoteRunsOverEveryModelInMemory) {
  Fixture f(0);
  const InsertReport r = f.insert(4, kChairAgain);
  EXPECT_TRUE(r.shortlist.empty());
  EXPECT_EQ(r.global_ranking.size(), 3u);  // measured all the same
  EXPECT_EQ(r.prefilter_candidates, r.exhaustive_candidates);
  EXPECT_TRUE(r.merged);
}

TEST(Shortlist, FollowsRemovalsAndMerges) {
  Fixture f(1);
  // The extinguisher's segment is withdrawn: its model is gone from the ranking.
  auto withdrawn = f.db->withdrawSegment("s", 2);
  ASSERT_TRUE(withdrawn.ok()) << withdrawn.status();
  ASSERT_TRUE(withdrawn->removed);
  const InsertReport merged = f.insert(4, kChairAgain);
  ASSERT_TRUE(merged.merged);
  EXPECT_EQ(std::count(merged.global_ranking.begin(), merged.global_ranking.end(),
                       f.extinguisher_id),
            0);
  // The merged chair (rebuilt with both segments) is ranked by its new descriptor: a third view
  // of the chair finds it first, and the ranking holds the chair and the box only.
  const InsertReport third = f.insert(5, kChair, View{0.0f, 10.0f});
  ASSERT_EQ(third.global_ranking.size(), 2u);
  EXPECT_EQ(third.global_ranking.front(), f.chair_id);
  EXPECT_EQ(third.shortlist, std::vector<int64_t>{f.chair_id});
}

}  // namespace
}  // namespace objdb::database
