#include "core/gsm/surface_noise.h"

#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "tests/support/sdf_grid.h"

namespace objdb::gsm {
namespace {

constexpr float kWall = 2.0f;        // a wall 2 m in front of the camera (looking along +z)
constexpr float kTruncation = 0.06f;

// The map: the wall's exact signed distance (positive in front of it), seen 10 times.
tsdf::TsdfLayer wallMap() {
  const objdb::testing::Sdf wall = [](const Eigen::Vector3f& p) { return kWall - p.z(); };
  return objdb::testing::sdfGrid(wall, Eigen::Vector3f(-1.5f, -1.2f, kWall - 0.1f),
                                 Eigen::Vector3f(1.5f, 1.2f, kWall + 0.1f), 0.02f, kTruncation)
      .layer;
}

// A depth image of the wall with Gaussian noise of `factor` times the model's σ at its depth.
DepthImage noisyWall(float factor, std::mt19937* rng) {
  const Intrinsics k = Intrinsics::vga();
  DepthImage depth(k.width, k.height, 0.0f);
  std::normal_distribution<float> noise(0.0f, factor * ModelParams().depthNoise(kWall));
  for (float& d : depth.data) d = kWall + noise(*rng);
  return depth;
}

float measuredScale(float factor, int frames) {
  const tsdf::TsdfLayer map = wallMap();
  std::mt19937 rng(7);
  SurfaceNoise session;
  for (int i = 0; i < frames; ++i) {
    SurfaceNoise frame;
    frame.sample(map, noisyWall(factor, &rng), Transform::Identity(), Intrinsics::vga(),
                 kTruncation);
    session.add(frame);
  }
  return session.scale();
}

TEST(SurfaceNoise, MeasuresTheDepthNoiseAsAMultipleOfTheModelsSigma) {
  // σ(2 m) is 6.1 mm: depth as noisy as the model says reads 1, twice as noisy 2, half 0.5.
  EXPECT_NEAR(measuredScale(1.0f, 10), 1.0f, 0.1f);
  EXPECT_NEAR(measuredScale(2.0f, 10), 2.0f, 0.2f);
  EXPECT_NEAR(measuredScale(0.5f, 10), 0.5f, 0.06f);
}

TEST(SurfaceNoise, IsUnknownUntilEnoughResidualsWereSeen) {
  EXPECT_EQ(SurfaceNoise().scale(), 0.0f);
  // One frame samples a 20 x 15 grid: 300 residuals, above kMinSamples.
  EXPECT_GT(measuredScale(1.0f, 1), 0.0f);
  // Nothing where the map has no surface, or where it was seen too few times.
  const objdb::testing::Sdf wall = [](const Eigen::Vector3f& p) { return kWall - p.z(); };
  const tsdf::TsdfLayer light =
      objdb::testing::sdfGrid(wall, Eigen::Vector3f(-1.5f, -1.2f, kWall - 0.1f),
                              Eigen::Vector3f(1.5f, 1.2f, kWall + 0.1f), 0.02f, kTruncation,
                              /*weight=*/1.0f)
          .layer;
  std::mt19937 rng(7);
  SurfaceNoise noise;
  noise.sample(light, noisyWall(1.0f, &rng), Transform::Identity(), Intrinsics::vga(),
               kTruncation);
  EXPECT_EQ(noise.samples(), 0);
  // A pose that is not finite adds nothing.
  Transform bad = Transform::Identity();
  bad.translation().x() = std::nan("");
  noise.sample(wallMap(), noisyWall(1.0f, &rng), bad, Intrinsics::vga(), kTruncation);
  EXPECT_EQ(noise.samples(), 0);
}

TEST(SurfaceNoise, APoseErrorReadsAsNoise) {
  // Exact depth from a camera 2.5 cm off where the pose says: every residual is 2.5 cm, about
  // 4 σ at the measured depth, so the scale reads 4 / 0.6745.
  const tsdf::TsdfLayer map = wallMap();
  const Intrinsics k = Intrinsics::vga();
  const float measured = kWall - 0.025f;
  DepthImage depth(k.width, k.height, measured);
  SurfaceNoise noise;
  noise.sample(map, depth, Transform::Identity(), k, kTruncation);
  EXPECT_NEAR(noise.scale(), 0.025f / ModelParams().depthNoise(measured) / 0.6745f, 0.05f);
}

}  // namespace
}  // namespace objdb::gsm
