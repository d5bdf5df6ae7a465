#include "core/completion/completion_score.h"

#include <gtest/gtest.h>

#include "core/sim/shapes.h"

namespace objdb::completion {
namespace {

Transform translation(double x, double y, double z) {
  Transform T = Transform::Identity();
  T.translation() = Eigen::Vector3d(x, y, z);
  return T;
}

TEST(AddedVertices, AreTheCompletedMeshsVerticesFarFromTheMeasuredOne) {
  const TriangleMesh floor = sim::makePlane(1.0f, 1.0f, 0.1f);
  TriangleMesh box = sim::makeBox(Eigen::Vector3f(0.2f, 0.2f, 0.2f));
  box.transform(translation(0.0, 0.0, 0.5));
  TriangleMesh completed = floor;
  completed.append(box);
  const auto measured = MeshDistance::create(floor, 0.02f).value();
  const auto added = addedVertices(completed, measured);
  EXPECT_EQ(added.size(), box.vertices.size());
  for (const auto& v : added) EXPECT_GT(v.z(), 0.3f);
}

TEST(FrameChecker, CallsPointsInFrontOfTheDepthSeenThrough) {
  Intrinsics k;
  k.width = 64;
  k.height = 48;
  k.fx = k.fy = 50.0;
  k.cx = 31.5;
  k.cy = 23.5;
  Frame frame;  // camera at the world origin looking along +z at a wall 2 m away
  frame.depth = DepthImage(k.width, k.height, 2.0f);
  frame.depth.at(0, 0) = 0.0f;  // one pixel without depth
  const Eigen::Vector3f corner(float((0 - k.cx) / k.fx), float((0 - k.cy) / k.fy), 1.0f);
  FrameChecker checker({
      {0.0f, 0.0f, 1.0f},    // in front of the wall: seen through
      {0.1f, 0.0f, 2.01f},   // on the wall
      {0.0f, 0.1f, 3.0f},    // behind it: no evidence
      {5.0f, 0.0f, 1.0f},    // outside the image
      {0.0f, 0.0f, -1.0f},   // behind the camera
      corner * 1.0f,         // on the pixel without depth
  });
  checker.add(frame, k);
  FrameEvidence e = checker.evidence();
  EXPECT_EQ(e.points, 6u);
  EXPECT_EQ(e.seen_through, 1u);
  EXPECT_EQ(e.seen_on_surface, 1u);
  // A second frame from farther back sees through the first three: the point in front of the
  // wall twice (seen through), the one on it once of two (a tie stays on the surface), the one
  // behind it once of once (seen through); and the corner point, which now lands on depth.
  Frame back = frame;
  back.T_world_camera = translation(0.0, 0.0, -1.0);
  back.depth = DepthImage(k.width, k.height, 5.0f);
  checker.add(back, k);
  e = checker.evidence();
  EXPECT_EQ(e.seen_through, 3u);
  EXPECT_EQ(e.seen_on_surface, 1u);
  // A third sees the wall point through again: now more frames see through it than on it.
  checker.add(back, k);
  e = checker.evidence();
  EXPECT_EQ(e.seen_through, 4u);
  EXPECT_EQ(e.seen_on_surface, 0u);
}

TEST(SurfaceGain, MeasuresTheRecoveredShareOfRepeatedObjectsAndItsCeiling) {
  // One box shape in two sessions: Monday measured only its top face, Tuesday all of it, and
  // Monday's completion recovered the whole box. A lone cylinder is not a repeated kind.
  const TriangleMesh box = sim::makeBox(Eigen::Vector3f(0.2f, 0.2f, 0.2f));
  const TriangleMesh cylinder = sim::makeCylinder(0.1f, 0.3f);
  const Transform monday_pose = translation(1.0, 0.0, 0.1), tuesday_pose = translation(-1.0, 2.0, 0.1);
  TriangleMesh top = sim::makePlane(0.2f, 0.2f, 0.05f);
  top.transform(translation(1.0, 0.0, 0.2));
  TriangleMesh monday_completed = box, tuesday = box;
  monday_completed.transform(monday_pose);
  tuesday.transform(tuesday_pose);
  const auto monday_before = MeshDistance::create(top, 0.02f).value();
  const auto monday_after = MeshDistance::create(monday_completed, 0.02f).value();
  const auto tuesday_index = MeshDistance::create(tuesday, 0.02f).value();
  const std::vector<TrueInstance> instances = {
      {"monday", "box", 1, &box, monday_pose},
      {"tuesday", "box", 1, &box, tuesday_pose},
      {"monday", "cylinder", 2, &cylinder, translation(0.0, 1.0, 0.0)},
  };
  const auto gain = surfaceGain(instances, {{"monday", &monday_before}, {"tuesday", &tuesday_index}},
                                {{"monday", &monday_after}, {"tuesday", &tuesday_index}}, 0.02f);
  ASSERT_TRUE(gain.ok()) << gain.status();
  ASSERT_EQ(gain->instances.size(), 2u);
  const InstanceGain& m = gain->instances[0];
  EXPECT_EQ(m.instance, 0u);
  // The top face and the 2 cm of the sides next to it: (0.04 + 4 · 0.2 · 0.02) / 0.24 ≈ 0.233.
  EXPECT_NEAR(m.before, 0.233, 0.01);
  EXPECT_NEAR(m.after, 1.0, 1e-9);
  EXPECT_NEAR(m.ceiling, 1.0, 1e-9);  // Tuesday saw all of it
  const InstanceGain& t = gain->instances[1];
  EXPECT_NEAR(t.before, 1.0, 1e-9);
  EXPECT_NEAR(gain->before, (m.before + 1.0) / 2, 1e-9);
  EXPECT_NEAR(gain->after, 1.0, 1e-9);

  // Without Tuesday the ceiling is what Monday saw.
  const auto alone = surfaceGain(instances, {{"monday", &monday_before}},
                                 {{"monday", &monday_after}}, 0.02f);
  ASSERT_TRUE(alone.ok());
  ASSERT_EQ(alone->instances.size(), 1u);
  EXPECT_NEAR(alone->instances[0].ceiling, m.before, 1e-9);
}

TEST(SurfaceGain, NamesWhatIsMissing) {
  const TriangleMesh box = sim::makeBox(Eigen::Vector3f(0.2f, 0.2f, 0.2f));
  const auto index = MeshDistance::create(box, 0.02f).value();
  const auto no_after = surfaceGain({{"monday", "box", 1, &box, Transform::Identity()}},
                                    {{"monday", &index}}, {}, 0.02f);
  EXPECT_EQ(no_after.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(std::string(no_after.status().message()).find("session monday"), std::string::npos);
  const auto no_mesh = surfaceGain({{"monday", "box", 7, nullptr, Transform::Identity()}},
                                   {{"monday", &index}}, {{"monday", &index}}, 0.02f);
  EXPECT_EQ(no_mesh.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(std::string(no_mesh.status().message()).find("instance 7"), std::string::npos);
}

}  // namespace
}  // namespace objdb::completion
