#include "core/sim/shapes.h"

#include <cmath>
#include <set>
#include <string>

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
    // Kitchen parts the size of a room (table, tall cabinet, rug) or of a hand (mug, bowl) fall
    // outside the lounge objects' band: KitchenKindsHaveTheirRealDimensions checks them.
    static const std::set<std::string> kOutsideBand = {
        "dining_table", "tall_cabinet", "counter_top", "rug", "baseboard", "mug", "bowl"};
    if (kOutsideBand.count(kind)) continue;
    EXPECT_GT(hi.z(), 0.15f) << kind;
    EXPECT_LT(hi.z(), 1.2f) << kind;
    EXPECT_LT((hi - lo).head<2>().maxCoeff(), 1.3f) << kind;
  }
}

TEST(ObjectLibrary, KitchenKindsHaveTheirRealDimensions) {
  struct Expected {
    const char* kind;
    Eigen::Vector3f lo, hi;  // bounds in the object frame, metres
  } cases[] = {
      {"dining_chair", {-0.21f, -0.21f, 0.0f}, {0.21f, 0.21f, 0.9f}},
      {"dining_table", {-0.7f, -0.4f, 0.0f}, {0.7f, 0.4f, 0.75f}},
      {"base_cabinet", {-0.3f, -0.3f, 0.0f}, {0.32f, 0.3f, 0.85f}},    // handles to 0.32
      {"wall_cabinet", {-0.175f, -0.3f, 0.0f}, {0.195f, 0.3f, 0.7f}},
      {"tall_cabinet", {-0.3f, -0.3f, 0.0f}, {0.32f, 0.3f, 2.0f}},
      {"counter_top", {-0.31f, -0.5f, 0.0f}, {0.31f, 0.5f, 0.04f}},
      {"shelf", {-0.125f, -0.4f, 0.0f}, {0.125f, 0.4f, 0.175f}},
      {"mug", {-0.04f, -0.04f, 0.0f}, {0.077f, 0.04f, 0.1f}},
      {"bottle", {-0.035f, -0.035f, 0.0f}, {0.035f, 0.035f, 0.315f}},
      {"rug", {-1.0f, -0.7f, 0.0f}, {1.0f, 0.7f, 0.01f}},
      {"baseboard", {-0.0075f, -0.5f, 0.0f}, {0.0075f, 0.5f, 0.08f}},
  };
  for (const auto& c : cases) {
    auto mesh = makeLibraryObject(c.kind);
    ASSERT_TRUE(mesh.ok()) << c.kind;
    Eigen::Vector3f lo, hi;
    ASSERT_TRUE(mesh->bounds(&lo, &hi));
    for (int k = 0; k < 3; ++k) {
      EXPECT_NEAR(lo[k], c.lo[k], 1e-3f) << c.kind << " axis " << k;
      EXPECT_NEAR(hi[k], c.hi[k], 1e-3f) << c.kind << " axis " << k;
    }
  }
  auto bowl = makeLibraryObject("bowl");
  ASSERT_TRUE(bowl.ok());
  Eigen::Vector3f lo, hi;
  ASSERT_TRUE(bowl->bounds(&lo, &hi));
  EXPECT_NEAR(hi.x() - lo.x(), 2 * 0.09 * std::sin(1.2), 0.005);  // rim ⌀ ≈ 0.17 m
  EXPECT_NEAR(hi.z(), 0.098 - 0.09 * std::cos(1.2), 1e-3);         // rim 6.5 cm high
}

TEST(ObjectLibrary, SizedKindsTakeTheirSizeAndNameAWrongOne) {
  auto cabinet = makeSizedLibraryObject("base_cabinet", {0.8f});
  ASSERT_TRUE(cabinet.ok()) << cabinet.status();
  Eigen::Vector3f lo, hi;
  ASSERT_TRUE(cabinet->bounds(&lo, &hi));
  EXPECT_NEAR(hi.y() - lo.y(), 0.8f, 1e-5f);
  auto rug = makeSizedLibraryObject("rug", {2.4f, 1.6f});
  ASSERT_TRUE(rug.ok());
  ASSERT_TRUE(rug->bounds(&lo, &hi));
  EXPECT_NEAR(hi.x() - lo.x(), 2.4f, 1e-5f);
  EXPECT_NEAR(hi.y() - lo.y(), 1.6f, 1e-5f);
  EXPECT_EQ(sizeArity("cow"), 0);
  EXPECT_EQ(sizeArity("counter_top"), 1);
  EXPECT_EQ(sizeArity("floor"), 2);
  auto wrong = makeSizedLibraryObject("counter_top", {1.0f, 0.6f});
  ASSERT_FALSE(wrong.ok());
  EXPECT_NE(wrong.status().message().find("counter_top takes size [length] (got 2 values)"),
            absl::string_view::npos)
      << wrong.status().message();
  auto negative = makeSizedLibraryObject("baseboard", {-1.0f});
  ASSERT_FALSE(negative.ok());
  EXPECT_NE(negative.status().message().find("baseboard size"), absl::string_view::npos);
  EXPECT_FALSE(makeSizedLibraryObject("cow", {1.0f}).ok());
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
