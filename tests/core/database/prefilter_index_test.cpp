#include "core/database/prefilter_index.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <random>
#include <tuple>
#include <vector>

#include <gtest/gtest.h>

namespace objdb::database {
namespace {

std::vector<model::Fpfh> randomDescriptors(std::mt19937* rng, size_t n) {
  std::uniform_real_distribution<float> u(0.0f, 100.0f);
  std::vector<model::Fpfh> out(n);
  for (auto& d : out) {
    for (float& x : d) x = u(*rng);
  }
  return out;
}

// The exact answer: every live descriptor, by distance, then owner, then put order.
struct Reference {
  struct Entry {
    int64_t owner;
    uint64_t sequence;
    model::Fpfh d;
  };
  std::map<int64_t, std::vector<Entry>> live;
  uint64_t next = 0;
  void put(int64_t id, const std::vector<model::Fpfh>& ds) {
    live.erase(id);
    for (const auto& d : ds) live[id].push_back({id, next++, d});
  }
  std::vector<int64_t> nearest(const model::Fpfh& q, int k) const {
    std::vector<std::tuple<float, int64_t, uint64_t>> all;
    for (const auto& [id, entries] : live) {
      for (const auto& e : entries) {
        float d2 = 0.0f;
        for (size_t c = 0; c < q.size(); ++c) d2 += (q[c] - e.d[c]) * (q[c] - e.d[c]);
        all.emplace_back(d2, e.owner, e.sequence);
      }
    }
    std::sort(all.begin(), all.end());
    std::vector<int64_t> out;
    for (size_t i = 0; i < all.size() && int(i) < k; ++i) out.push_back(std::get<1>(all[i]));
    return out;
  }
};

std::vector<int64_t> owners(const std::vector<PrefilterIndex::Neighbour>& found) {
  std::vector<int64_t> out;
  for (const auto& n : found) out.push_back(n.owner);
  return out;
}

TEST(PrefilterIndex, AnswersAsOneTreeOverTheLiveDescriptorsThroughPutsReplacementsAndErasures) {
  std::mt19937 rng(7);
  PrefilterIndex index;
  Reference reference;
  std::uniform_int_distribution<int64_t> pick(1, 40);
  std::uniform_int_distribution<int> op(0, 9), size(0, 30);
  for (int step = 0; step < 400; ++step) {
    const int64_t id = pick(rng);
    if (op(rng) < 7) {
      const auto ds = randomDescriptors(&rng, size_t(size(rng)));
      index.put(id, ds);
      reference.put(id, ds);
    } else {
      index.erase(id);
      reference.live.erase(id);
    }
    size_t live = 0;
    for (const auto& [owner, entries] : reference.live) live += entries.size();
    ASSERT_EQ(index.size(), live) << "step " << step;
    if (step % 10 != 0) continue;
    for (const auto& q : randomDescriptors(&rng, 5)) {
      for (const int k : {1, 8, 64}) {
        ASSERT_EQ(owners(index.nearest(q, k)), reference.nearest(q, k))
            << "step " << step << ", k " << k;
        ASSERT_EQ(owners(index.nearestExhaustive(q, k)), reference.nearest(q, k))
            << "step " << step << ", k " << k;
      }
    }
  }
}

TEST(PrefilterIndex, BuildsEachDescriptorLogarithmicallyOftenNotOncePerInsert) {
  std::mt19937 rng(11);
  PrefilterIndex index;
  const size_t models = 512, per_model = 20;
  for (size_t i = 0; i < models; ++i) index.put(int64_t(i + 1), randomDescriptors(&rng, per_model));
  const size_t total = models * per_model;
  EXPECT_EQ(index.size(), total);
  // A full rebuild per insert builds 1 + 2 + … + 512 models' worth (2.6 M descriptors); the
  // binary counter builds each descriptor at most log2(512) + 1 = 10 times.
  EXPECT_LE(index.rebuilt(), total * 10);
  EXPECT_LE(index.trees(), size_t(10));
  // Erasing most models shrinks what is kept: half-dead trees are rebuilt or dropped.
  for (size_t i = 0; i < models; i += 1) {
    if (i % 8 != 0) index.erase(int64_t(i + 1));
  }
  EXPECT_EQ(index.size(), (models / 8) * per_model);
  const auto found = index.nearest(randomDescriptors(&rng, 1)[0], 2000);
  EXPECT_EQ(found.size(), (models / 8) * per_model);
  for (const auto& n : found) EXPECT_EQ((n.owner - 1) % 8, 0);
}

TEST(PrefilterIndex, ALoadOnTwoThreadsAnswersAsOnOne) {
  std::mt19937 rng(13);
  std::vector<std::vector<model::Fpfh>> descriptors;
  for (int m = 0; m < 30; ++m) descriptors.push_back(randomDescriptors(&rng, size_t(5 + m % 7)));
  Reference reference;
  for (int m = 0; m < 30; ++m) reference.put(m + 1, descriptors[size_t(m)]);
  // Each load takes the lists it is given (and leaves them empty): one copy each.
  std::vector<std::vector<model::Fpfh>> for_one = descriptors, for_two = descriptors;
  std::vector<std::pair<int64_t, std::vector<model::Fpfh>*>> models_one, models_two;
  for (int m = 0; m < 30; ++m) {
    models_one.emplace_back(m + 1, &for_one[size_t(m)]);
    models_two.emplace_back(m + 1, &for_two[size_t(m)]);
  }
  PrefilterIndex one, two;
  one.load(models_one, 1);
  two.load(models_two, 2);
  for (const auto& taken : for_two) EXPECT_TRUE(taken.empty());
  EXPECT_EQ(one.trees(), 1u);
  EXPECT_EQ(two.trees(), 2u);
  EXPECT_EQ(two.size(), one.size());
  for (const auto& q : randomDescriptors(&rng, 20)) {
    EXPECT_EQ(owners(two.nearest(q, 16)), reference.nearest(q, 16));
    EXPECT_EQ(owners(two.nearest(q, 16)), owners(one.nearest(q, 16)));
  }
  // Changes after the load work on either.
  two.erase(3);
  reference.live.erase(3);
  two.put(31, descriptors[0]);
  reference.put(31, descriptors[0]);
  for (const auto& q : randomDescriptors(&rng, 10)) {
    EXPECT_EQ(owners(two.nearest(q, 16)), reference.nearest(q, 16));
  }
}

TEST(PrefilterIndex, LoadedModelsAreFoundAndReplacedLikePutOnes) {
  std::mt19937 rng(3);
  const auto a = randomDescriptors(&rng, 10), b = randomDescriptors(&rng, 10);
  auto a_taken = a, b_taken = b;
  PrefilterIndex index;
  index.load({{1, &a_taken}, {2, &b_taken}});
  EXPECT_EQ(index.size(), 20u);
  EXPECT_EQ(index.nearest(a[3], 1).at(0).owner, 1);
  EXPECT_FLOAT_EQ(index.nearest(a[3], 1).at(0).similarity, 1.0f);
  index.put(1, b);  // model 1 now holds b's descriptors: ties go to the lower owner
  EXPECT_EQ(index.size(), 20u);
  EXPECT_EQ(owners(index.nearest(b[0], 2)), (std::vector<int64_t>{1, 2}));
  index.erase(2);
  index.erase(1);
  EXPECT_EQ(index.size(), 0u);
  EXPECT_TRUE(index.nearest(a[0], 5).empty());
}

float squared(const model::Fpfh& a, const model::Fpfh& b) {
  float d2 = 0.0f;
  for (size_t c = 0; c < a.size(); ++c) d2 += (a[c] - b[c]) * (a[c] - b[c]);
  return d2;
}

// Descriptors of `models` models, each a cloud of `per_model` around a centre of its own.
std::map<int64_t, std::vector<model::Fpfh>> clusteredModels(std::mt19937* rng, int models,
                                                            size_t per_model, float spread) {
  std::normal_distribution<float> noise(0.0f, spread);
  std::map<int64_t, std::vector<model::Fpfh>> out;
  for (int m = 1; m <= models; ++m) {
    const model::Fpfh centre = randomDescriptors(rng, 1)[0];
    auto& ds = out[m];
    for (size_t i = 0; i < per_model; ++i) {
      model::Fpfh d = centre;
      for (float& x : d) x += noise(*rng);
      ds.push_back(d);
    }
  }
  return out;
}

TEST(PrefilterIndex, AnApproximateSearchStaysWithinItsBoundAndFindsTheRightModels) {
  std::mt19937 rng(5);
  const auto models = clusteredModels(&rng, 60, 40, 4.0f);
  const float epsilon = 2.0f;
  PrefilterIndex approximate(epsilon), again(epsilon);
  Reference reference;
  for (const auto& [id, ds] : models) {
    approximate.put(id, ds);
    again.put(id, ds);
    reference.put(id, ds);
  }
  size_t same_owner = 0, asked = 0;
  for (const auto& [id, ds] : models) {
    for (size_t i = 0; i < ds.size(); i += 10) {
      model::Fpfh q = ds[i];
      for (float& x : q) x += 1.0f;  // a nearby view of the same surface
      const int k = 20;
      const auto found = approximate.nearest(q, k);
      const auto exact = approximate.nearestExhaustive(q, k);
      ASSERT_EQ(found.size(), size_t(k));
      ASSERT_EQ(owners(exact), reference.nearest(q, k));
      // Deterministic: the same puts answer the same.
      ASSERT_EQ(owners(found), owners(again.nearest(q, k)));
      // FLANN's bound on squared distances: none farther than (1 + ε) times the exact k-th.
      std::vector<float> all;
      for (const auto& [owner, entries] : reference.live) {
        for (const auto& e : entries) all.push_back(squared(q, e.d));
      }
      std::nth_element(all.begin(), all.begin() + (k - 1), all.end());
      const float kth = all[size_t(k - 1)];
      for (const auto& n : found) {
        float nearest_of_owner = std::numeric_limits<float>::max();
        for (const auto& d : models.at(n.owner)) {
          nearest_of_owner = std::min(nearest_of_owner, squared(q, d));
        }
        EXPECT_LE(nearest_of_owner, (1.0f + epsilon) * kth * 1.0001f);
      }
      for (const auto& n : found) same_owner += n.owner == id ? 1 : 0;
      asked += found.size();
    }
  }
  // The vote sees what the exact search sees: the query's own model.
  EXPECT_EQ(same_owner, asked);
}

TEST(PrefilterIndex, GivesBackEachModelsDescriptorsThroughTreeMergesAndRebuilds) {
  std::mt19937 rng(23);
  PrefilterIndex index;
  std::map<int64_t, std::vector<model::Fpfh>> models;
  std::vector<std::pair<int64_t, std::vector<model::Fpfh>*>> loaded;
  std::map<int64_t, std::vector<model::Fpfh>> taken;  // load() empties the lists it takes
  for (int64_t id = 1; id <= 5; ++id) {
    models[id] = randomDescriptors(&rng, 7 + size_t(id));
    taken[id] = models[id];
    loaded.emplace_back(id, &taken[id]);
  }
  index.load(loaded, 2);
  std::uniform_int_distribution<int64_t> pick(1, 40);
  for (int step = 0; step < 200; ++step) {
    const int64_t id = pick(rng);
    if (step % 4 == 3) {
      index.erase(id);
      models.erase(id);
    } else {
      models[id] = randomDescriptors(&rng, 1 + size_t(step % 9));
      index.put(id, models[id]);
    }
    for (const auto& [m, descriptors] : models) {
      ASSERT_EQ(index.descriptorsOf(m), descriptors) << "model " << m << " at step " << step;
    }
  }
  EXPECT_TRUE(index.descriptorsOf(1000).empty());
}

}  // namespace
}  // namespace objdb::database
