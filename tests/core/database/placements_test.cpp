// "What is here?" over placements with known poses: regions, bad regions, changes between two
// sessions.
#include <gtest/gtest.h>

#include <cmath>

#include "core/database/placements.h"
#include "core/model/object_model.h"

namespace objdb::database {
namespace {

// A unit-ish box model (0..0.4 x 0..0.4 x 0..0.8 in its frame) placed at (x, y, 0), turned by yaw.
Placement at(int64_t id, double x, double y, double yaw = 0.0) {
  return {id, poseFromXyzYaw({x, y, 0.0}, yaw),
          Eigen::AlignedBox3d(Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(0.4, 0.4, 0.8))};
}

TEST(Placements, TheCentreAndTheWorldBoxFollowThePose) {
  const Placement p = at(1, 2.0, 1.0, M_PI / 2);
  // The box's middle (0.2, 0.2, 0.4) turned by 90° about z: (-0.2, 0.2, 0.4), then moved.
  EXPECT_TRUE(p.centre().isApprox(Eigen::Vector3d(1.8, 1.2, 0.4), 1e-9));
  const Eigen::AlignedBox3d box = p.worldBox();
  EXPECT_TRUE(box.min().isApprox(Eigen::Vector3d(1.6, 1.0, 0.0), 1e-9));
  EXPECT_TRUE(box.max().isApprox(Eigen::Vector3d(2.0, 1.4, 0.8), 1e-9));
}

TEST(Placements, APlacementIsInARegionWhenItsCentreIs) {
  const Placement p = at(1, 2.0, 1.0);  // centre (2.2, 1.2, 0.4)
  Region box;
  box.box = Eigen::AlignedBox3d(Eigen::Vector3d(2.0, 1.0, 0.0), Eigen::Vector3d(2.5, 1.5, 1.0));
  EXPECT_TRUE(inRegion(p, box));
  box.box = Eigen::AlignedBox3d(Eigen::Vector3d(2.3, 1.0, 0.0), Eigen::Vector3d(2.5, 1.5, 1.0));
  EXPECT_FALSE(inRegion(p, box)) << "overlaps the box, but its centre is outside";
  Region ball;
  ball.centre = Eigen::Vector3d(2.2, 1.2, 0.0);
  ball.radius_m = 0.41;
  EXPECT_TRUE(inRegion(p, ball));
  ball.radius_m = 0.39;
  EXPECT_FALSE(inRegion(p, ball));
}

TEST(Placements, BadRegionsNameTheField) {
  Region r;
  r.box = Eigen::AlignedBox3d(Eigen::Vector3d(0, 2, 0), Eigen::Vector3d(1, 1, 1));
  Status s = validateRegion(r);
  EXPECT_TRUE(absl::IsInvalidArgument(s));
  EXPECT_NE(s.message().find("box.min.y 2 > box.max.y 1"), std::string::npos) << s;
  r.box = Eigen::AlignedBox3d(Eigen::Vector3d(0, 0, NAN), Eigen::Vector3d(1, 1, 1));
  s = validateRegion(r);
  EXPECT_NE(s.message().find("box.min.z"), std::string::npos) << s;
  Region ball;
  ball.radius_m = 0.0;
  s = validateRegion(ball);
  EXPECT_NE(s.message().find("radius_m"), std::string::npos) << s;
  ball.radius_m = 1.0;
  ball.centre.x() = INFINITY;
  s = validateRegion(ball);
  EXPECT_NE(s.message().find("centre"), std::string::npos) << s;
  ball.centre.x() = 0.0;
  EXPECT_TRUE(validateRegion(ball).ok());
}

TEST(Placements, ChangesBetweenTwoSessionsHaveTheKnownAnswer) {
  // Monday: chair 1 at (0, 0), box 2 at (2, 0), lamp 3 at (4, 0), two stools 5 at (0, 3), (1, 3).
  // Tuesday: chair 1 turned in place (its centre 2 cm away), box 2 one metre on, lamp gone,
  // plant 4 new, one stool taken away.
  const std::vector<Placement> monday = {at(1, 0, 0), at(2, 2, 0), at(3, 4, 0), at(5, 0, 3),
                                         at(5, 1, 3)};
  const std::vector<Placement> tuesday = {at(1, 0.02, 0), at(2, 3, 0), at(4, 6, 0),
                                          at(5, 0, 3)};
  const SessionChanges c = changesBetween(monday, tuesday, model::kSamePlaceM);
  ASSERT_EQ(c.added.size(), 1u);
  EXPECT_EQ(c.added[0].model_id, 4);
  EXPECT_TRUE(c.added[0].before.empty());
  ASSERT_EQ(c.added[0].after.size(), 1u);
  ASSERT_EQ(c.removed.size(), 1u);
  EXPECT_EQ(c.removed[0].model_id, 3);
  ASSERT_EQ(c.moved.size(), 2u);
  EXPECT_EQ(c.moved[0].model_id, 2);
  EXPECT_NEAR(c.moved[0].moved_m, 1.0, 1e-9);
  EXPECT_EQ(c.moved[1].model_id, 5);  // one of two stools gone: its place has none the day after
  EXPECT_NEAR(c.moved[1].moved_m, 1.0, 1e-9);
  EXPECT_EQ(c.unchanged, 1u);  // the chair: 2 cm is one place

  // The other way round: what was added is removed, and the stool's change is the same.
  const SessionChanges back = changesBetween(tuesday, monday, model::kSamePlaceM);
  ASSERT_EQ(back.removed.size(), 1u);
  EXPECT_EQ(back.removed[0].model_id, 4);
  ASSERT_EQ(back.added.size(), 1u);
  EXPECT_EQ(back.added[0].model_id, 3);
  EXPECT_EQ(back.moved.size(), 2u);
}

}  // namespace
}  // namespace objdb::database
