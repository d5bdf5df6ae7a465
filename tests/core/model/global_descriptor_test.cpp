#include "core/model/global_descriptor.h"

#include <cmath>
#include <numeric>
#include <random>

#include <gtest/gtest.h>

namespace objdb::model {
namespace {

// FPFH-like histograms: three sub-histograms of 11 bins, each summing to 100, drawn around a
// profile so that descriptors of one "shape" resemble each other.
std::vector<Fpfh> descriptorsAround(const Fpfh& profile, size_t n, std::mt19937* rng) {
  std::normal_distribution<float> noise(0.0f, 2.0f);
  std::vector<Fpfh> out(n);
  for (Fpfh& d : out) {
    for (int h = 0; h < 3; ++h) {
      float sum = 0.0f;
      for (int b = 0; b < 11; ++b) {
        float& v = d[size_t(h * 11 + b)];
        v = std::max(0.0f, profile[size_t(h * 11 + b)] + noise(*rng));
        sum += v;
      }
      for (int b = 0; b < 11; ++b) d[size_t(h * 11 + b)] *= sum > 0 ? 100.0f / sum : 0.0f;
    }
  }
  return out;
}

Fpfh peakedProfile(int peak) {
  Fpfh p{};
  for (int h = 0; h < 3; ++h) {
    for (int b = 0; b < 11; ++b) {
      const int d = std::abs(b - (peak + 3 * h) % 11);
      p[size_t(h * 11 + b)] = 40.0f * std::exp(-0.5f * float(d * d));
    }
  }
  return p;
}

float norm(const std::vector<float>& v) {
  return std::sqrt(std::inner_product(v.begin(), v.end(), v.begin(), 0.0f));
}

TEST(GlobalDescriptor, TheHellingerFormHasUnitLengthAndKeepsProportions) {
  Fpfh d{};
  d[0] = 25.0f;
  d[5] = 75.0f;
  const Fpfh h = hellinger(d);
  EXPECT_NEAR(h[0], 0.5f, 1e-6f);
  EXPECT_NEAR(h[5], std::sqrt(0.75f), 1e-6f);
  float sum = 0.0f;
  for (float v : h) sum += v * v;
  EXPECT_NEAR(sum, 1.0f, 1e-6f);
  // Scaling the histogram changes nothing; an empty one maps to zero.
  for (float& v : d) v *= 3.0f;
  EXPECT_NEAR(hellinger(d)[5], std::sqrt(0.75f), 1e-6f);
  EXPECT_EQ(hellinger(Fpfh{}), Fpfh{});
}

TEST(GlobalDescriptor, IsAUnitVectorOfTheCodebooksSizeAndZeroForNoDescriptors) {
  ASSERT_GE(fpfhCodebook().words, 8) << "the trained codebook is in fpfh_codebook.inc";
  EXPECT_EQ(globalDescriptorSize(), fpfhCodebook().words * 33);
  std::mt19937 rng(3);
  const auto g = globalDescriptor(descriptorsAround(peakedProfile(2), 300, &rng));
  ASSERT_EQ(int(g.size()), globalDescriptorSize());
  EXPECT_NEAR(norm(g), 1.0f, 1e-4f);
  const auto none = globalDescriptor({});
  ASSERT_EQ(int(none.size()), globalDescriptorSize());
  EXPECT_EQ(norm(none), 0.0f);
  EXPECT_EQ(globalSimilarity(g, none), 0.0f);
  EXPECT_EQ(globalSimilarity(g, std::vector<float>(3, 1.0f)), 0.0f);  // another length
}

TEST(GlobalDescriptor, DoesNotDependOnTheOrderOfTheDescriptors) {
  std::mt19937 rng(5);
  auto ds = descriptorsAround(peakedProfile(4), 200, &rng);
  const auto a = globalDescriptor(ds);
  std::shuffle(ds.begin(), ds.end(), rng);
  const auto b = globalDescriptor(ds);
  EXPECT_NEAR(globalSimilarity(a, b), 1.0f, 1e-5f);
}

TEST(GlobalDescriptor, ASubsetOfOneShapesDescriptorsIsNearerItThanAnotherShape) {
  // A partial view holds part of a model's keypoints: its vector stays nearest that model's.
  std::mt19937 rng(7);
  const auto chair = descriptorsAround(peakedProfile(1), 600, &rng);
  auto mug = descriptorsAround(peakedProfile(7), 600, &rng);
  const std::vector<Fpfh> view(chair.begin(), chair.begin() + 200);
  const auto g_chair = globalDescriptor(chair), g_mug = globalDescriptor(mug),
             g_view = globalDescriptor(view);
  EXPECT_GT(globalSimilarity(g_view, g_chair), globalSimilarity(g_view, g_mug) + 0.2f)
      << globalSimilarity(g_view, g_chair) << " vs " << globalSimilarity(g_view, g_mug);
}

}  // namespace
}  // namespace objdb::model
