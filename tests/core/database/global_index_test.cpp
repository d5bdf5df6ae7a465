#include "core/database/global_index.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <random>
#include <vector>

#include <gtest/gtest.h>

namespace objdb::database {
namespace {

std::vector<float> unitVector(std::mt19937* rng, int dims) {
  std::normal_distribution<float> n(0.0f, 1.0f);
  std::vector<float> v(static_cast<size_t>(dims));
  float norm2 = 0.0f;
  for (float& x : v) {
    x = n(*rng);
    norm2 += x * x;
  }
  for (float& x : v) x /= std::sqrt(norm2);
  return v;
}

// The exact answer by a scan of a map: similarity descending, then id ascending.
std::vector<int64_t> reference(const std::map<int64_t, std::vector<float>>& live,
                               const std::vector<float>& q, int n, int64_t exclude) {
  std::vector<std::pair<float, int64_t>> all;
  for (const auto& [id, v] : live) {
    if (id == exclude) continue;
    float dot = 0.0f;
    for (size_t i = 0; i < q.size(); ++i) dot += q[i] * v[i];
    all.emplace_back(-dot, id);
  }
  std::sort(all.begin(), all.end());
  std::vector<int64_t> out;
  for (size_t i = 0; i < all.size() && (n <= 0 || int(i) < n); ++i) out.push_back(all[i].second);
  return out;
}

std::vector<int64_t> ids(const std::vector<GlobalIndex::Hit>& hits) {
  std::vector<int64_t> out;
  for (const auto& h : hits) out.push_back(h.id);
  return out;
}

TEST(GlobalIndex, AnswersAsAScanThroughPutsReplacementsAndErasures) {
  std::mt19937 rng(11);
  constexpr int kDims = 48;
  GlobalIndex index;
  std::map<int64_t, std::vector<float>> live;
  std::uniform_int_distribution<int64_t> id(1, 300);
  std::uniform_int_distribution<int> op(0, 9);
  for (int step = 0; step < 3000; ++step) {
    const int64_t m = id(rng);
    if (op(rng) < 7) {
      live[m] = unitVector(&rng, kDims);
      index.put(m, live[m]);
    } else {
      live.erase(m);
      index.erase(m);
    }
    ASSERT_EQ(index.size(), live.size());
    if (step % 100 == 0) {
      const auto q = unitVector(&rng, kDims);
      const int64_t exclude = id(rng);
      EXPECT_EQ(ids(index.nearest(q, 10, exclude)), reference(live, q, 10, exclude)) << step;
      EXPECT_EQ(ids(index.nearest(q, 0)), reference(live, q, 0, 0)) << step;
    }
  }
}

TEST(GlobalIndex, ReportsTheCosineAndLeavesOutWhatCannotCompare) {
  GlobalIndex index;
  index.put(1, {1.0f, 0.0f});
  index.put(2, {0.6f, 0.8f});
  index.put(3, {0.0f, 0.0f});        // nothing to compare: not held
  index.put(4, {1.0f, 0.0f, 0.0f});  // another length: not held
  EXPECT_EQ(index.size(), 2u);
  EXPECT_FALSE(index.contains(3));
  EXPECT_FALSE(index.contains(4));
  const auto hits = index.nearest({1.0f, 0.0f}, 5);
  ASSERT_EQ(hits.size(), 2u);
  EXPECT_EQ(hits[0].id, 1);
  EXPECT_FLOAT_EQ(hits[0].similarity, 1.0f);
  EXPECT_EQ(hits[1].id, 2);
  EXPECT_FLOAT_EQ(hits[1].similarity, 0.6f);
  EXPECT_TRUE(index.nearest({1.0f, 0.0f, 0.0f}, 5).empty());  // a query of another length
  // A model whose descriptor becomes empty leaves.
  index.put(2, {});
  EXPECT_EQ(ids(index.nearest({0.0f, 1.0f}, 5)), std::vector<int64_t>{1});
}

}  // namespace
}  // namespace objdb::database
