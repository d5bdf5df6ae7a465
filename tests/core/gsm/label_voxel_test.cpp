#include "core/gsm/label_voxel.h"

#include <gtest/gtest.h>

namespace objdb::gsm {
namespace {

TEST(LabelVoxel, MainLabelIsTheMostVoted) {
  LabelVoxel v;
  EXPECT_TRUE(v.empty());
  EXPECT_EQ(v.mainLabel(), 0u);
  for (int i = 0; i < 3; ++i) v.vote(7);
  for (int i = 0; i < 5; ++i) v.vote(9);
  v.vote(7);
  EXPECT_EQ(v.mainLabel(), 9u);
  EXPECT_EQ(v.countOf(7), 4u);
  EXPECT_EQ(v.countOf(9), 5u);
  EXPECT_EQ(v.countOf(1), 0u);
  EXPECT_EQ(sizeof(LabelVoxel), 16u);
}

TEST(LabelVoxel, CountsHalveInsteadOfWrappingAndKeepTheMainLabel) {
  LabelVoxel v;
  for (int i = 0; i < 100; ++i) v.vote(2);
  for (int i = 0; i < 1000; ++i) v.vote(1);  // would wrap an 8-bit counter several times
  EXPECT_EQ(v.mainLabel(), 1u);
  EXPECT_GT(v.countOf(1), 128u);
  EXPECT_LE(v.countOf(1), 255u);
  EXPECT_LT(v.countOf(2), v.countOf(1));
}

TEST(LabelVoxel, AFullVoxelEvictsTheWeakestLabelWhichInheritsItsCount) {
  LabelVoxel v;
  for (int i = 0; i < 10; ++i) v.vote(1);
  for (int i = 0; i < 6; ++i) v.vote(2);
  for (int i = 0; i < 2; ++i) v.vote(3);
  v.vote(4);  // replaces label 3 (2 votes) and counts 3
  EXPECT_EQ(v.countOf(3), 0u);
  EXPECT_EQ(v.countOf(4), 3u);
  EXPECT_EQ(v.mainLabel(), 1u);
  // A label voted in more than a third of the votes can never be evicted.
  LabelVoxel w;
  for (int round = 0; round < 200; ++round) {
    w.vote(100);
    w.vote(uint32_t(200 + round));  // a stream of one-off labels
  }
  EXPECT_EQ(w.mainLabel(), 100u);
}

}  // namespace
}  // namespace objdb::gsm

namespace objdb::gsm {
namespace {

TEST(LabelVoxel, SingleLabelAblationLosesAPluralityThatTheHistoryKeeps) {
  // Votes 1 ×4, then 2 ×3, then 3 ×3: label 1 has the most votes (40 %). One label + confidence
  // spends its confidence on the interleaved others and ends on label 3.
  LabelVoxel history, single;
  auto both = [&](Label l, int n) {
    for (int i = 0; i < n; ++i) {
      history.vote(l);
      single.voteSingle(l);
    }
  };
  both(1, 4);
  both(2, 3);
  both(3, 3);
  EXPECT_EQ(history.mainLabel(), 1u);
  EXPECT_EQ(single.mainLabel(), 3u);
  EXPECT_EQ(single.countOf(1), 0u);
}

}  // namespace
}  // namespace objdb::gsm
