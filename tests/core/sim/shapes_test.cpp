#include "core/sim/shapes.h"

#include <cmath>

#include <gtest/gtest.h>

#include "core/sim/object_library.h"

namespace objdb::sim {
namespace {

TEST(Shapes, BoxHasExactAreaAndVolume) {
  const TriangleMesh box = makeBox({1.0f, 2.0f, 3.0f});
  EXPECT_NEAR(box.surfaceArea(), 2 * (2 + 3 + 6), 1e-5);
  EXPECT_NEAR(box.signedVolume(), 6.0, 1e-5);
  EXPECT_TRUE(box.validate().ok());
}

TEST(Shapes, FinelyTessellatedPrimitivesApproachAnalyticVolumes) {
  const double r = 0.5, h = 1.2;
  EXPECT_NEAR(makeSphere(r, 64, 128).signedVolume(), 4.0 / 3.0 * M_PI * r * r * r, 0.01 * M_PI * r * r * r);
  EXPECT_NEAR(makeSphere(r, 64, 128).surfaceArea(), 4 * M_PI * r * r, 0.01 * 4 * M_PI * r * r);
  EXPECT_NEAR(makeCylinder(r, h, 256).signedVolume(), M_PI * r * r * h, 0.005 * M_PI * r * r * h);
  EXPECT_NEAR(makeCone(r, h, 256).signedVolume(), M_PI * r * r * h / 3, 0.005 * M_PI * r * r * h);
  const double R = 0.4, t = 0.1;
  EXPECT_NEAR(makeTorus(R, t, 2 * M_PI, 128, 64).signedVolume(), 2 * M_PI * M_PI * R * t * t,
              0.01 * 2 * M_PI * M_PI * R * t * t);
  // Half a torus arc, closed at its ends, holds half the volume.
  EXPECT_NEAR(makeTorus(R, t, M_PI, 64, 64).signedVolume(), M_PI * M_PI * R * t * t,
              0.01 * M_PI * M_PI * R * t * t);
}

TEST(Shapes, PlaneIsSplitIntoSmallCells) {
  const TriangleMesh plane = makePlane(3.0f, 2.0f, 0.5f);
  EXPECT_EQ(plane.triangles.size(), 6u * 4u * 2u);
  EXPECT_NEAR(plane.surfaceArea(), 6.0, 1e-5);
}

TEST(ObjectLibrary, EveryKindBuildsAValidOutwardMeshOfPlausibleSize) {
  for (const auto& kind : libraryKinds()) {
    auto mesh = makeLibraryObject(kind);
    ASSERT_TRUE(mesh.ok()) << kind << ": " << mesh.status();
    EXPECT_TRUE(mesh->validate().ok()) << kind;
    EXPECT_EQ(mesh->normals.size(), mesh->vertices.size()) << kind;
    Eigen::Vector3f lo, hi;
    ASSERT_TRUE(mesh->bounds(&lo, &hi));
    if (kind == "floor" || kind == "wall") continue;
    EXPECT_GT(mesh->signedVolume(), 0.0) << kind << " is inside out";
    EXPECT_NEAR(lo.z(), 0.0f, 0.01f) << kind << " does not stand on z = 0";
    EXPECT_GT(hi.z(), 0.15f) << kind;
    EXPECT_LT(hi.z(), 1.2f) << kind;
    EXPECT_LT((hi - lo).head<2>().maxCoeff(), 1.3f) << kind;
  }
}

TEST(ObjectLibrary, UnknownKindListsTheKnownOnes) {
  auto mesh = makeLibraryObject("sofa");
  ASSERT_FALSE(mesh.ok());
  EXPECT_NE(mesh.status().message().find("unknown object kind 'sofa'"), absl::string_view::npos);
  EXPECT_NE(mesh.status().message().find("round_chair"), absl::string_view::npos);
}

TEST(ObjectLibrary, WallStandsOnTheFloorFacingPlusX) {
  const TriangleMesh wall = makeWall(4.0f, 2.5f);
  Eigen::Vector3f lo, hi;
  ASSERT_TRUE(wall.bounds(&lo, &hi));
  EXPECT_NEAR(lo.z(), 0.0f, 1e-5f);
  EXPECT_NEAR(hi.z(), 2.5f, 1e-5f);
  EXPECT_NEAR(hi.y() - lo.y(), 4.0f, 1e-5f);
  EXPECT_NEAR(hi.x() - lo.x(), 0.0f, 1e-5f);
  const auto& t = wall.triangles.front();
  const Eigen::Vector3f n = (wall.vertices[t[1]] - wall.vertices[t[0]])
                                .cross(wall.vertices[t[2]] - wall.vertices[t[0]]);
  EXPECT_GT(n.x(), 0.0f);
}

}  // namespace
}  // namespace objdb::sim
