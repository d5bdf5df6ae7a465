// The purity, structure leakage and excess extent `objdb eval` prints against ground truth
// (client/db_score.h), on hand-made placements whose answer is known: a model that is 70 points
// of a chair along 0.7 m and 30 points of floor beyond it, and a clean chair seen twice.
#include "client/db_score.h"

#include <gtest/gtest.h>

namespace objdb::cli {
namespace {

// `n` points along x from `from` (1 cm apart), each voted onto `instance` once, into `p`.
void addPoints(Row* row, Placement* p, int n, double from, int instance) {
  for (int i = 0; i < n; ++i) {
    row->points.emplace_back(float(from + 0.01 * i), 0.0f, 0.0f);
    p->point_votes.resize(row->points.size());
    p->point_votes.back().add(instance);
    ++p->votes[instance];
  }
}

GroundTruth truth() {
  GroundTruth t;
  for (const std::string session : {"monday", "tuesday"}) {
    io::GroundTruthObject floor;
    floor.id = 1;
    floor.category = "floor";
    floor.is_structure = true;
    t[session][1] = floor;
    io::GroundTruthObject chair;
    chair.id = 3;
    chair.category = "chair";
    t[session][3] = chair;
  }
  return t;
}

TEST(DbScore, PurityLeakageAndExcessExtentOfAModelWithFloorFlakes) {
  Row row;
  row.summary.id = 7;
  Placement p;
  p.session = "monday";
  addPoints(&row, &p, 70, 0.0, 3);   // the chair: 0.00–0.69 m
  addPoints(&row, &p, 30, 0.70, 1);  // floor flakes: 0.70–0.99 m
  row.placements.push_back(p);
  const TruthScore s = scoreTruth({row}, truth());
  ASSERT_EQ(s.pure_models, 1u);
  EXPECT_NEAR(s.model_purity, 0.70, 1e-9);
  EXPECT_EQ(s.impure_models, 1u);
  EXPECT_NEAR(s.leakage, 0.30, 1e-9);
  ASSERT_EQ(s.pure_placements, 1u);
  EXPECT_NEAR(s.placement_purity, 0.70, 1e-9);
  EXPECT_EQ(s.impure_placements, 1u);
  ASSERT_EQ(s.extent_models, 1u);
  EXPECT_NEAR(s.extent_excess, 0.30, 0.011);  // 0.99 m across, its chair points 0.69 m
  EXPECT_EQ(s.extent_over, 1u);
  ASSERT_EQ(s.impure.size(), 1u);
  EXPECT_NE(s.impure[0].find("also floor 30 %"), std::string::npos) << s.impure[0];
  ASSERT_EQ(s.junk.size(), 1u);
  EXPECT_NE(s.junk[0].find("model 7 (chair"), std::string::npos) << s.junk[0];
}

TEST(DbScore, AChairModelSeenInTwoSessionsWithoutJunkIsPure) {
  Row row;
  row.summary.id = 9;
  for (const std::string session : {"monday", "tuesday"}) {
    Placement p;
    p.session = session;
    row.points.clear();
    addPoints(&row, &p, 50, 0.0, 3);
    row.placements.push_back(p);
  }
  const TruthScore s = scoreTruth({row}, truth());
  ASSERT_EQ(s.pure_models, 1u);
  EXPECT_DOUBLE_EQ(s.model_purity, 1.0);
  EXPECT_EQ(s.impure_models, 0u);
  EXPECT_DOUBLE_EQ(s.leakage, 0.0);
  EXPECT_EQ(s.pure_placements, 2u);
  EXPECT_EQ(s.extent_over, 0u);
  EXPECT_NEAR(s.extent_excess, 0.0, 1e-6);
  EXPECT_TRUE(s.junk.empty());
}

TEST(DbScore, AModelMostlyOnTheFloorIsNotScoredAsAnObject) {
  Row row;
  Placement p;
  p.session = "monday";
  addPoints(&row, &p, 20, 0.0, 3);
  addPoints(&row, &p, 80, 0.2, 1);
  row.placements.push_back(p);
  const TruthScore s = scoreTruth({row}, truth());
  EXPECT_EQ(s.pure_models, 0u);
  EXPECT_EQ(s.extent_models, 0u);
}

}  // namespace
}  // namespace objdb::cli
