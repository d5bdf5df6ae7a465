#include "core/sim/renderer.h"

#include <cmath>

#include <gtest/gtest.h>

#include "core/sim/shapes.h"

namespace objdb::sim {
namespace {

// A camera at the origin looking along world +x... simpler: world = camera frame (identity pose).
TEST(Renderer, FrontoParallelPlaneRendersExactDepth) {
  const TriangleMesh plane = makePlane(20.0f, 20.0f, 1.0f);  // z = 0 plane, normal +z
  // Put the plane at z = 2.0 in front of an identity camera.
  Transform T = Transform::Identity();
  T.translation() = Eigen::Vector3d(0, 0, 2.0);
  const Renderer renderer(Intrinsics::vga());
  RenderOutput out;
  renderer.render({RenderInstance{&plane, T, 7}}, Transform::Identity(), &out);
  for (size_t i = 0; i < out.depth.size(); ++i) {
    ASSERT_NEAR(out.depth.data[i], 2.0f, 1e-5f) << "pixel " << i;
    ASSERT_EQ(out.instances.data[i], 7);
  }
  // Centre pixel looks straight at the plane: cos = 1.
  EXPECT_NEAR(out.cos_incidence.at(320, 240), 1.0f, 1e-3f);
}

TEST(Renderer, TiltedPlaneMatchesRayPlaneIntersection) {
  const TriangleMesh plane = makePlane(30.0f, 30.0f, 1.0f);
  // Plane through (0, 0, 3) with normal tilted 40° about the camera x axis.
  Transform T = Transform::Identity();
  T.linear() = Eigen::AngleAxisd(40.0 * M_PI / 180.0, Eigen::Vector3d::UnitX()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(0, 0, 3.0);
  const Eigen::Vector3d n = T.linear() * Eigen::Vector3d::UnitZ();
  const Intrinsics k = Intrinsics::vga();
  const Renderer renderer(k);
  RenderOutput out;
  renderer.render({RenderInstance{&plane, T, 1}}, Transform::Identity(), &out);
  for (int v = 0; v < k.height; v += 7) {
    for (int u = 0; u < k.width; u += 7) {
      const Eigen::Vector3d ray((u - k.cx) / k.fx, (v - k.cy) / k.fy, 1.0);
      const double z = n.dot(T.translation()) / n.dot(ray);  // depth along the optical axis
      ASSERT_NEAR(out.depth.at(u, v), z, 1e-4 * z) << u << "," << v;
    }
  }
}

// Slab test of a ray from the origin against an oriented box; returns depth (z) or 0.
double rayBoxDepth(const Eigen::Vector3d& ray, const Transform& T_camera_box,
                   const Eigen::Vector3d& half) {
  const Transform T_box_camera = T_camera_box.inverse();
  const Eigen::Vector3d o = T_box_camera.translation();
  const Eigen::Vector3d d = T_box_camera.linear() * ray;
  double t0 = 0.0, t1 = 1e9;
  for (int a = 0; a < 3; ++a) {
    if (std::abs(d[a]) < 1e-12) {
      if (std::abs(o[a]) > half[a]) return 0.0;
      continue;
    }
    double ta = (-half[a] - o[a]) / d[a], tb = (half[a] - o[a]) / d[a];
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
  }
  return t0 <= t1 ? t0 * ray.z() : 0.0;
}

TEST(Renderer, BoxAtKnownPoseHasRightSilhouetteDepthAndIds) {
  const Eigen::Vector3d size(0.6, 0.4, 0.3);
  const TriangleMesh box = makeBox(size.cast<float>());
  Transform T_camera_box = Transform::Identity();
  T_camera_box.linear() = (Eigen::AngleAxisd(0.5, Eigen::Vector3d::UnitY()) *
                           Eigen::AngleAxisd(-0.3, Eigen::Vector3d::UnitX()))
                              .toRotationMatrix();
  T_camera_box.translation() = Eigen::Vector3d(0.1, -0.05, 1.8);
  // Render through a non-identity camera pose to exercise T_world_camera.
  Transform T_world_camera = Transform::Identity();
  T_world_camera.linear() = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  T_world_camera.translation() = Eigen::Vector3d(1.0, 2.0, -0.5);
  const Transform T_world_box = T_world_camera * T_camera_box;

  const Intrinsics k = Intrinsics::vga();
  const Renderer renderer(k);
  RenderOutput out;
  renderer.render({RenderInstance{&box, T_world_box, 42}}, T_world_camera, &out);

  int inside = 0, mismatched = 0;
  for (int v = 0; v < k.height; ++v) {
    for (int u = 0; u < k.width; ++u) {
      const Eigen::Vector3d ray((u - k.cx) / k.fx, (v - k.cy) / k.fy, 1.0);
      const double expected = rayBoxDepth(ray, T_camera_box, size / 2);
      const bool hit = out.instances.at(u, v) == 42;
      inside += expected > 0;
      if ((expected > 0) != hit) {
        ++mismatched;
        continue;
      }
      if (hit) {
        ASSERT_NEAR(out.depth.at(u, v), expected, 1e-4) << u << "," << v;
      } else {
        ASSERT_EQ(out.depth.at(u, v), 0.0f);
      }
    }
  }
  EXPECT_GT(inside, 20000);
  // Disagreement only where a pixel centre lies on an edge within float rounding.
  EXPECT_LE(mismatched, 4) << "of " << inside << " silhouette pixels";
}

TEST(Renderer, NearerObjectOccludesFartherOneAndNearPlaneClips) {
  const TriangleMesh plane = makePlane(20.0f, 20.0f, 20.0f);  // two huge triangles
  Transform far = Transform::Identity();
  far.translation() = Eigen::Vector3d(0, 0, 3.0);
  const TriangleMesh box = makeBox({0.5f, 0.5f, 0.5f});
  Transform near = Transform::Identity();
  near.translation() = Eigen::Vector3d(0, 0, 1.0);
  const Renderer renderer(Intrinsics::vga());
  RenderOutput out;
  renderer.render({RenderInstance{&plane, far, 1}, RenderInstance{&box, near, 2}},
                  Transform::Identity(), &out);
  EXPECT_EQ(out.instances.at(320, 240), 2);
  EXPECT_NEAR(out.depth.at(320, 240), 0.75f, 1e-5f);
  EXPECT_EQ(out.instances.at(5, 5), 1);
  EXPECT_NEAR(out.depth.at(5, 5), 3.0f, 1e-5f);

  // A plane seen at a grazing slope that starts behind the camera: clipped, no garbage.
  Transform floor = Transform::Identity();
  floor.linear() = Eigen::AngleAxisd(-M_PI / 2, Eigen::Vector3d::UnitX()).toRotationMatrix();
  floor.translation() = Eigen::Vector3d(0, 1.0, 0);  // 1 m below the camera (y down)
  renderer.render({RenderInstance{&plane, floor, 3}}, Transform::Identity(), &out);
  EXPECT_EQ(out.instances.at(320, 100), 0);            // above the horizon: nothing
  EXPECT_EQ(out.instances.at(320, 470), 3);            // below: floor
  EXPECT_NEAR(out.depth.at(320, 470), 525.0 / (470 - 239.5), 1e-3);
  for (float d : out.depth.data) ASSERT_TRUE(d == 0.0f || (d >= 0.05f && std::isfinite(d)));
}

}  // namespace
}  // namespace objdb::sim
