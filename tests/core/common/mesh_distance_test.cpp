#include "core/common/mesh_distance.h"

#include <cmath>
#include <limits>
#include <random>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "tests/support/meshes.h"

namespace objdb {
namespace {

using ::testing::HasSubstr;

TriangleMesh unitCube() { return objdb::testing::unitCubeMesh(); }

// Exact distance from p to the surface of the unit cube.
float cubeSurfaceDistance(const Eigen::Vector3f& p) {
  const Eigen::Vector3f q = (p - Eigen::Vector3f::Constant(0.5f)).cwiseAbs() -
                            Eigen::Vector3f::Constant(0.5f);
  const float outside = q.cwiseMax(0.0f).norm();
  const float inside = std::min(q.maxCoeff(), 0.0f);
  return std::abs(outside + inside);
}

TEST(PointTriangleDistance, InteriorEdgeVertexAndDegenerateCases) {
  const Eigen::Vector3f a(0, 0, 0), b(1, 0, 0), c(0, 1, 0);
  EXPECT_FLOAT_EQ(pointTriangleDistance({0.2f, 0.2f, 0.5f}, a, b, c), 0.5f);   // above inside
  EXPECT_FLOAT_EQ(pointTriangleDistance({0.5f, -0.3f, 0.4f}, a, b, c), 0.5f);  // beyond edge ab
  EXPECT_FLOAT_EQ(pointTriangleDistance({2.0f, 0.0f, 0.0f}, a, b, c), 1.0f);   // beyond vertex b
  EXPECT_NEAR(pointTriangleDistance({1.0f, 1.0f, 0.0f}, a, b, c), std::sqrt(0.5f), 1e-6f);
  // Collinear and collapsed triangles act as a segment and a point.
  EXPECT_FLOAT_EQ(pointTriangleDistance({0.5f, 2.0f, 0.0f}, a, b, {2, 0, 0}), 2.0f);
  EXPECT_FLOAT_EQ(pointTriangleDistance({0.0f, 0.0f, 3.0f}, a, a, a), 3.0f);
}

TEST(MeshDistance, MatchesTheAnalyticDistanceToACube) {
  auto index = MeshDistance::create(unitCube(), 0.3f);
  ASSERT_TRUE(index.ok()) << index.status();
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> coord(-0.5f, 1.5f);
  int within = 0;
  for (int i = 0; i < 2000; ++i) {
    const Eigen::Vector3f p(coord(rng), coord(rng), coord(rng));
    const float truth = cubeSurfaceDistance(p);
    const float d = index->distance(p);
    if (truth <= 0.3f - 1e-4f) {
      ++within;
      ASSERT_NEAR(d, truth, 1e-5f) << p.transpose();
    } else if (truth > 0.3f + 1e-4f) {
      ASSERT_TRUE(std::isinf(d)) << p.transpose() << " truth " << truth << " got " << d;
    }
  }
  EXPECT_GT(within, 500);  // the sample really exercised the near range
}

TEST(MeshDistance, RejectsBadInput) {
  EXPECT_THAT(std::string(MeshDistance::create(unitCube(), 0.0f).status().message()),
              HasSubstr("max_distance must be positive"));
  EXPECT_THAT(
      std::string(MeshDistance::create(unitCube(), std::numeric_limits<float>::quiet_NaN())
                      .status()
                      .message()),
      HasSubstr("max_distance"));
  TriangleMesh bad = unitCube();
  bad.vertices[3].x() = std::numeric_limits<float>::infinity();
  EXPECT_THAT(std::string(MeshDistance::create(bad, 0.1f).status().message()),
              HasSubstr("vertex 3 is not finite"));
  TriangleMesh out_of_range = unitCube();
  out_of_range.triangles[0][1] = 99;
  EXPECT_FALSE(MeshDistance::create(out_of_range, 0.1f).ok());
  const auto huge = MeshDistance::create(unitCube(), 1e-4f, 1000);
  EXPECT_EQ(huge.status().code(), absl::StatusCode::kResourceExhausted);
  EXPECT_THAT(std::string(huge.status().message()), HasSubstr("larger distance"));
  // A query at NaN is "nothing near", not a crash.
  auto index = MeshDistance::create(unitCube(), 0.1f);
  ASSERT_TRUE(index.ok());
  EXPECT_TRUE(std::isinf(index->distance(Eigen::Vector3f::Constant(NAN))));
}

TEST(SampleSurface, CoversTheSurfaceEvenly) {
  const TriangleMesh cube = unitCube();
  auto points = sampleSurface(cube, 0.02f);
  ASSERT_TRUE(points.ok());
  // Area 6 m² at 2 cm spacing: 15,000 points (up to rounding per triangle).
  EXPECT_NEAR(double(points->size()), 15000.0, 2.0);
  auto index = MeshDistance::create(cube, 0.05f);
  ASSERT_TRUE(index.ok());
  for (const auto& p : *points) ASSERT_LT(index->distance(p), 1e-5f);
  // Every face gets its share: one sixth of the points on each face.
  int on_top = 0;
  for (const auto& p : *points) on_top += std::abs(p.z() - 1.0f) < 1e-6f ? 1 : 0;
  EXPECT_NEAR(on_top, 2500, 10);
  EXPECT_FALSE(sampleSurface(cube, -1.0f).ok());
}

TEST(SampleSurface, EveryTriangleGetsAPointWhenAsked) {
  TriangleMesh tiny;
  tiny.vertices = {{0, 0, 0}, {0.001f, 0, 0}, {0, 0.001f, 0}};
  tiny.triangles = {{0, 1, 2}};
  EXPECT_EQ(sampleSurface(tiny, 0.1f)->size(), 0u);
  EXPECT_EQ(sampleSurface(tiny, 0.1f, true)->size(), 1u);
}

TEST(SummarizeDistances, StatisticsAndShares) {
  const float inf = std::numeric_limits<float>::infinity();
  const DistanceStats s = summarizeDistances({0.4f, 0.1f, 0.3f, inf, 0.2f});
  EXPECT_EQ(s.count, 4u);
  EXPECT_EQ(s.beyond, 1u);
  EXPECT_NEAR(s.mean, 0.25, 1e-6);
  EXPECT_FLOAT_EQ(float(s.median), 0.3f);
  EXPECT_FLOAT_EQ(float(s.max), 0.4f);
  EXPECT_NEAR(s.shareWithin(0.25), 2.0 / 5.0, 1e-12);  // the beyond one counts as outside
  EXPECT_EQ(summarizeDistances({}).count, 0u);
}

}  // namespace
}  // namespace objdb
