#include "core/common/mesh.h"

#include <cmath>
#include <limits>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "tests/support/meshes.h"

namespace objdb {
namespace {

using ::testing::HasSubstr;

TriangleMesh unitCube() { return objdb::testing::unitCubeMesh(); }

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

// Appending a mesh with nothing in it (a block without surface) keeps the colours and normals
// (it used to drop them: every object's surface cloud came without colours).
TEST(TriangleMesh, AppendingAnEmptyMeshKeepsColoursAndNormals) {
  TriangleMesh a = unitCube();
  a.computeVertexNormals();
  a.colors.assign(a.vertices.size(), Rgb8{1, 2, 3});
  a.append(TriangleMesh());
  EXPECT_EQ(a.colors.size(), a.vertices.size());
  EXPECT_EQ(a.normals.size(), a.vertices.size());
  TriangleMesh b = unitCube();
  b.colors.assign(b.vertices.size(), Rgb8{4, 5, 6});
  a.append(b);  // b has no normals: they go; both have colours: they stay
  EXPECT_EQ(a.colors.size(), a.vertices.size());
  EXPECT_TRUE(a.normals.empty());
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
