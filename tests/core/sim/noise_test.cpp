#include "core/sim/noise.h"

#include <cmath>
#include <set>

#include <gtest/gtest.h>

namespace objdb::sim {
namespace {

DepthImage constantDepth(int w, int h, float z) { return DepthImage(w, h, z); }

TEST(DepthNoise, AxialNoiseHasConfiguredMeanAndSigma) {
  DepthNoiseParams p;
  p.quantum_m = 0.0f;  // measure the Gaussian alone
  for (float z : {1.0f, 2.0f, 3.5f}) {
    DepthImage depth = constantDepth(400, 400, z);
    const Image<float> cos(400, 400, 1.0f);
    const NoiseStats stats = applyDepthNoise(p, 3, cos, &depth);
    // The image border is a depth edge (invalid outside): only interior pixels are unbiased.
    double sum = 0, sum2 = 0;
    size_t n = 0;
    for (int v = 1; v < 399; ++v) {
      for (int u = 1; u < 399; ++u) {
        const double e = depth.at(u, v) - z;
        sum += e;
        sum2 += e * e;
        ++n;
      }
    }
    const double mean = sum / n, sigma = std::sqrt(sum2 / n - mean * mean);
    EXPECT_NEAR(mean, 0.0, 0.0002) << "z=" << z;
    EXPECT_NEAR(sigma, p.sigmaAt(z), 0.02 * p.sigmaAt(z)) << "z=" << z;
    EXPECT_EQ(stats.grazing_dropouts, 0u);
    EXPECT_EQ(stats.out_of_range, 0u);
  }
  EXPECT_NEAR(p.sigmaAt(2.0f), 0.0012 + 0.0019 * 1.6 * 1.6, 1e-7);
}

TEST(DepthNoise, QuantisesToTheConfiguredStep) {
  DepthNoiseParams p;
  p.quantum_m = 0.004f;
  DepthImage depth = constantDepth(50, 50, 1.5f);
  applyDepthNoise(p, 0, Image<float>(50, 50, 1.0f), &depth);
  for (float d : depth.data) {
    if (d == 0.0f) continue;
    const double steps = d / 0.004;
    ASSERT_NEAR(steps, std::round(steps), 1e-3) << d;
  }
}

TEST(DepthNoise, DisparityQuantisationStepGrowsWithDepthSquared) {
  DepthNoiseParams p;
  p.sigma_base_m = 0.0f;  // exact depth in, so only the quantisation acts
  p.sigma_quadratic = 0.0f;
  p.quantum_m = 0.0f;
  p.edge_dropout_probability = 0.0f;
  p.disparity_quantum = 0.0028f;
  for (float z0 : {1.0f, 3.0f}) {
    // A slow ramp ±0.1 m around z0: several quantisation levels, no depth edges.
    const int w = 2000;
    DepthImage depth(w, 1, 0.0f);
    for (int u = 0; u < w; ++u) depth.at(u, 0) = z0 - 0.1f + 0.2f * float(u) / float(w - 1);
    const DepthImage clean = depth;
    applyDepthNoise(p, 0, Image<float>(w, 1, 1.0f), &depth);
    std::set<float> levels;
    for (int u = 0; u < w; ++u) {
      const float z = clean.at(u, 0), d = depth.at(u, 0);
      ASSERT_GT(d, 0.0f);
      EXPECT_LE(std::abs(d - z), 0.55f * p.disparityStepAt(z)) << "z=" << z;
      levels.insert(d);
    }
    ASSERT_GE(levels.size(), 3u) << "z0=" << z0;
    float previous = -1.0f;
    for (float level : levels) {
      if (previous > 0.0f) {
        const float expected = p.disparityStepAt(0.5f * (level + previous));
        EXPECT_NEAR(level - previous, expected, 0.02f * expected) << "z0=" << z0;
      }
      previous = level;
    }
  }
  EXPECT_NEAR(p.disparityStepAt(3.0f), 0.0252f, 1e-6f);  // Kinect-like: 2.5 cm steps at 3 m
  p.disparity_quantum = -0.001f;
  EXPECT_NE(p.validate().message().find("disparity_quantum"), absl::string_view::npos);
  EXPECT_EQ(DepthNoiseParams().disparity_quantum, 0.0f);  // off unless a scene asks for it
}

TEST(DepthNoise, GrazingDropoutFollowsTheConfiguredRamp) {
  DepthNoiseParams p;  // ramp 70° → 85°
  const float angle = 80.0f * float(M_PI) / 180.0f;
  DepthImage depth = constantDepth(300, 300, 2.0f);
  const NoiseStats stats = applyDepthNoise(p, 0, Image<float>(300, 300, std::cos(angle)), &depth);
  const double expected = (80.0 - 70.0) / (85.0 - 70.0);
  EXPECT_NEAR(double(stats.grazing_dropouts) / (300 * 300), expected, 0.01);
  DepthImage straight = constantDepth(300, 300, 2.0f);
  EXPECT_EQ(applyDepthNoise(p, 0, Image<float>(300, 300, 0.5f), &straight).grazing_dropouts, 0u);
}

TEST(DepthNoise, DropsAboutHalfOfTheEdgePixels) {
  DepthNoiseParams p;
  DepthImage depth(200, 200, 0.0f);
  for (int v = 50; v < 150; ++v) {
    for (int u = 50; u < 150; ++u) depth.at(u, v) = 1.0f;  // a square with a border to nothing
  }
  const NoiseStats stats = applyDepthNoise(p, 0, Image<float>(200, 200, 1.0f), &depth);
  const double edge_pixels = 4 * 100 - 4;
  EXPECT_NEAR(stats.edge_dropouts / edge_pixels, p.edge_dropout_probability, 0.08);
  EXPECT_EQ(depth.at(20, 20), 0.0f);  // nothing stays nothing
}

TEST(DepthNoise, OutOfRangeBecomesNoMeasurementAndNaNStaysInvalid) {
  DepthNoiseParams p;
  DepthImage depth(3, 1, 0.0f);
  depth.at(0, 0) = 0.1f;   // closer than min_depth_m
  depth.at(1, 0) = 9.0f;   // beyond max_depth_m
  depth.at(2, 0) = std::nanf("");
  const NoiseStats stats = applyDepthNoise(p, 0, Image<float>(3, 1, 1.0f), &depth);
  EXPECT_EQ(stats.out_of_range, 2u);
  for (float d : depth.data) EXPECT_EQ(d, 0.0f);
}

TEST(DepthNoise, SameSeedSameImageOtherSeedOtherImage) {
  DepthNoiseParams p;
  const Image<float> cos(64, 48, 0.9f);
  DepthImage a = constantDepth(64, 48, 2.0f), b = a, c = a, d = a;
  applyDepthNoise(p, 5, cos, &a);
  applyDepthNoise(p, 5, cos, &b);
  EXPECT_EQ(a, b);
  p.seed = 2;
  applyDepthNoise(p, 5, cos, &c);
  EXPECT_NE(a, c);
  p.seed = 1;
  applyDepthNoise(p, 6, cos, &d);  // another frame of the same seed differs too
  EXPECT_NE(a, d);
}

TEST(DepthNoise, DisabledLeavesDepthUntouched) {
  DepthNoiseParams p;
  p.enabled = false;
  DepthImage depth = constantDepth(10, 10, 1.234f);
  const DepthImage before = depth;
  applyDepthNoise(p, 0, Image<float>(10, 10, 0.0f), &depth);
  EXPECT_EQ(depth, before);
}

TEST(DepthNoise, ValidateNamesTheBadField) {
  DepthNoiseParams p;
  p.quantum_m = std::nanf("");
  EXPECT_NE(p.validate().message().find("quantum_m"), absl::string_view::npos);
  p = DepthNoiseParams();
  p.grazing_start_deg = 88.0f;
  EXPECT_FALSE(p.validate().ok());
  EXPECT_TRUE(DepthNoiseParams().validate().ok());
}

TEST(DepthNoise, UniformAndNormalDrawsHaveTheRightMoments) {
  double su = 0, sn = 0, sn2 = 0;
  const int n = 200000;
  for (int i = 0; i < n; ++i) {
    const double u = uniform01(9, 1, i, 0);
    ASSERT_GT(u, 0.0);
    ASSERT_LT(u, 1.0);
    su += u;
    const double g = standardNormal(9, 1, i, 2);
    sn += g;
    sn2 += g * g;
  }
  EXPECT_NEAR(su / n, 0.5, 0.003);
  EXPECT_NEAR(sn / n, 0.0, 0.01);
  EXPECT_NEAR(sn2 / n, 1.0, 0.01);
}

}  // namespace
}  // namespace objdb::sim
