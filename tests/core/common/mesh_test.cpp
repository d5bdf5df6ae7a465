#include "core/common/mesh.h"

#include <cmath>
#include <limits>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace objdb {
namespace {

using ::testing::HasSubstr;

// Axis-aligned unit cube [0,1]^3, 12 outward-facing triangles.
TriangleMesh unitCube() {
  TriangleMesh mesh;
  for (int i = 0; i < 8; ++i) {
    mesh.vertices.emplace_back(float(i & 1), float((i >> 1) & 1), float((i >> 2) & 1));
  }
  const int faces[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4},
                           {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (const auto& f : faces) {
    mesh.triangles.emplace_back(f[0], f[1], f[2]);
    mesh.triangles.emplace_back(f[0], f[2], f[3]);
  }
  return mesh;
}

TEST(TriangleMesh, UnitCubeHasAreaSixAndVolumeOne) {
  const TriangleMesh cube = unitCube();
  EXPECT_TRUE(cube.validate().ok());
  EXPECT_NEAR(cube.surfaceArea(), 6.0, 1e-9);
  EXPECT_NEAR(cube.signedVolume(), 1.0, 1e-9);
  Eigen::Vector3f lo, hi;
  ASSERT_TRUE(cube.bounds(&lo, &hi));
  EXPECT_EQ(lo, Eigen::Vector3f::Zero());
  EXPECT_EQ(hi, Eigen::Vector3f::Ones());
}

TEST(TriangleMesh, TransformKeepsVolumeAndMovesBounds) {
  TriangleMesh cube = unitCube();
  cube.transform(poseFromXyzYaw(Eigen::Vector3d(10, 0, 0), 0.5));
  EXPECT_NEAR(cube.signedVolume(), 1.0, 1e-4);
  EXPECT_NEAR(cube.surfaceArea(), 6.0, 1e-4);
  Eigen::Vector3f lo, hi;
  ASSERT_TRUE(cube.bounds(&lo, &hi));
  EXPECT_GT(lo.x(), 9.0f);
}

TEST(TriangleMesh, VertexNormalsPointOutward) {
  TriangleMesh cube = unitCube();
  cube.computeVertexNormals();
  ASSERT_EQ(cube.normals.size(), 8u);
  const Eigen::Vector3f centre(0.5f, 0.5f, 0.5f);
  for (size_t i = 0; i < 8; ++i) {
    EXPECT_NEAR(cube.normals[i].norm(), 1.0f, 1e-5f);
    EXPECT_GT(cube.normals[i].dot(cube.vertices[i] - centre), 0.0f);
  }
}

TEST(TriangleMesh, AppendOffsetsIndices) {
  TriangleMesh a = unitCube();
  a.append(unitCube());
  EXPECT_EQ(a.vertices.size(), 16u);
  EXPECT_EQ(a.triangles.size(), 24u);
  EXPECT_EQ(a.triangles[12], Eigen::Vector3i(8, 10, 11));
  EXPECT_TRUE(a.validate().ok());
}

TEST(TriangleMesh, ValidateCatchesBadIndices) {
  TriangleMesh mesh = unitCube();
  mesh.triangles[5] = Eigen::Vector3i(0, 8, 1);
  Status s = mesh.validate();
  ASSERT_FALSE(s.ok());
  EXPECT_THAT(std::string(s.message()), HasSubstr("triangle 5"));
  EXPECT_THAT(std::string(s.message()), HasSubstr("vertex 8"));

  mesh = unitCube();
  mesh.triangles[0] = Eigen::Vector3i(-1, 1, 2);
  s = mesh.validate();
  ASSERT_FALSE(s.ok());
  EXPECT_THAT(std::string(s.message()), HasSubstr("vertex -1"));
}

TEST(TriangleMesh, ValidateCatchesAttributeSizesAndNonFiniteVertices) {
  TriangleMesh mesh = unitCube();
  mesh.normals.resize(3);
  EXPECT_THAT(std::string(mesh.validate().message()), HasSubstr("3 normals for 8 vertices"));

  mesh = unitCube();
  mesh.colors.resize(9);
  EXPECT_FALSE(mesh.validate().ok());

  mesh = unitCube();
  mesh.vertices[4].y() = std::numeric_limits<float>::quiet_NaN();
  EXPECT_THAT(std::string(mesh.validate().message()), HasSubstr("vertex 4"));
}

}  // namespace
}  // namespace objdb
