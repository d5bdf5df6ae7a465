#include "core/sim/scene.h"

#include <gtest/gtest.h>

#include "core/sim/lounge.h"
#include "tests/support/temp_dir.h"

namespace objdb::sim {
namespace {

bool contains(const Status& s, absl::string_view text) {
  return s.message().find(text) != absl::string_view::npos;
}

TEST(Scene, JsonRoundTripKeepsEverything) {
  Scene scene = twoBoxesScene("tango", 12);
  scene.noise.seed = 99;
  scene.noise.sigma_quadratic = 0.003f;
  scene.objects[0].scale = Eigen::Vector3f(1.0f, 2.0f, 0.5f);
  auto parsed = parseSceneJson(sceneToJson(scene), "/tmp");
  ASSERT_TRUE(parsed.ok()) << parsed.status();
  EXPECT_EQ(parsed->name, scene.name);
  EXPECT_EQ(parsed->intrinsics, scene.intrinsics);
  EXPECT_EQ(parsed->noise.seed, 99u);
  EXPECT_FLOAT_EQ(parsed->noise.sigma_quadratic, 0.003f);
  ASSERT_EQ(parsed->objects.size(), scene.objects.size());
  for (size_t i = 0; i < scene.objects.size(); ++i) {
    EXPECT_EQ(parsed->objects[i].id, scene.objects[i].id);
    EXPECT_EQ(parsed->objects[i].category, scene.objects[i].category);
    EXPECT_TRUE(parsed->objects[i].T_world_object.isApprox(scene.objects[i].T_world_object, 1e-9));
    EXPECT_EQ(parsed->objects[i].scale, scene.objects[i].scale);
    EXPECT_EQ(parsed->objects[i].size, scene.objects[i].size);
    EXPECT_EQ(parsed->objects[i].albedo, scene.objects[i].albedo);
  }
  EXPECT_EQ(parsed->trajectory.frames, 12);
  ASSERT_EQ(parsed->trajectory.keyframes.size(), scene.trajectory.keyframes.size());
}

TEST(Scene, BadFilesGiveErrorsNamingTheField) {
  const std::string traj = R"("trajectory": {"keyframes": [{"position": [0,0,1], "look_at": [1,0,0]},
                                                           {"position": [0,1,1], "look_at": [1,0,0]}]})";
  struct Case {
    std::string json, expected;
  } cases[] = {
      {"{", "not valid JSON"},
      {R"({"colour": 1})", "unknown key 'colour'"},
      {R"({"camera": "kinect2"})", "unknown camera preset 'kinect2'"},
      {R"({"objects": [{"id": 0, "category": "cow"}], )" + traj + "}", "objects[0].id"},
      {R"({"objects": [{"id": 1, "category": "cow"}, {"id": 1, "category": "cow"}], )" + traj + "}",
       "id 1 is used twice"},
      {R"({"objects": [{"id": 1, "category": "cow", "pose": {"t": [0, "a", 0]}}], )" + traj + "}",
       "objects[0].pose.t"},
      {R"({"objects": [{"id": 1, "category": "cow", "pose": {"t": [0,0,0], "q": [0,0,0,2]}}], )" +
           traj + "}",
       "squared norm"},
      {R"({"objects": [{"id": 1, "category": "cow", "albedo": [0, 300, 0]}], )" + traj + "}",
       "objects[0].albedo"},
      {R"({"noise": {"quantum_m": -1}, )" + traj + "}", "quantum_m"},
      {R"({"trajectory": {"keyframes": [{"position": [0,0,1], "look_at": [1,0,0]}]}})",
       "at least 2 keyframes"},
      {R"({"trajectory": {"frames": 0, "keyframes": []}})", "trajectory.frames"},
      {R"({"depth_scale_m": 1E99999})", "not valid JSON"},  // threw out_of_range (a crash)
  };
  for (const auto& c : cases) {
    auto scene = parseSceneJson(c.json, ".");
    ASSERT_FALSE(scene.ok()) << c.json;
    EXPECT_TRUE(contains(scene.status(), c.expected))
        << "expected '" << c.expected << "' in: " << scene.status().message();
  }
}

TEST(Scene, UnknownKindAndMissingMeshFileAreNamedWhenBuilding) {
  Scene scene = twoBoxesScene();
  scene.objects[0].mesh = "sofa";
  auto built = buildScene(scene);
  ASSERT_FALSE(built.ok());
  EXPECT_TRUE(contains(built.status(), "object 1"));
  EXPECT_TRUE(contains(built.status(), "sofa"));
  scene.objects[0].mesh = "file:missing/chair.obj";
  scene.base_dir = "/nonexistent";
  built = buildScene(scene);
  ASSERT_FALSE(built.ok());
  EXPECT_TRUE(contains(built.status(), "chair.obj"));
}

TEST(Scene, LoadSceneFileNamesTheFile) {
  testing::TempDir dir;
  ASSERT_TRUE(testing::writeTextFile(dir / "bad.json", R"({"objects": 3})"));
  auto scene = loadSceneFile(dir / "bad.json");
  ASSERT_FALSE(scene.ok());
  EXPECT_TRUE(contains(scene.status(), "bad.json"));
  EXPECT_EQ(loadSceneFile(dir / "none.json").status().code(), absl::StatusCode::kNotFound);
}

TEST(Trajectory, PassesThroughKeyframesAndLooksAtTargets) {
  TrajectorySpec spec;
  spec.frames = 21;
  spec.keyframes = {{{0, 0, 1}, {2, 0, 0}}, {{1, 1, 1.5}, {2, 1, 0}}, {{2, 3, 1}, {3, 3, 0}}};
  auto poses = sampleTrajectory(spec);
  ASSERT_TRUE(poses.ok());
  ASSERT_EQ(poses->size(), 21u);
  EXPECT_TRUE(poses->front().translation().isApprox(Eigen::Vector3d(0, 0, 1), 1e-9));
  EXPECT_TRUE((*poses)[10].translation().isApprox(Eigen::Vector3d(1, 1, 1.5), 1e-9));
  EXPECT_TRUE(poses->back().translation().isApprox(Eigen::Vector3d(2, 3, 1), 1e-9));
  // Optical axis (camera z) through the look-at point; image down (camera y) has world z < 0.
  const Eigen::Vector3d z = (*poses)[10].linear().col(2);
  EXPECT_TRUE(z.isApprox((Eigen::Vector3d(2, 1, 0) - Eigen::Vector3d(1, 1, 1.5)).normalized(), 1e-9));
  for (const auto& T : *poses) {
    EXPECT_LT(T.linear().col(1).z(), 0.0);
    EXPECT_TRUE(validateTransform(T, "pose").ok());
  }
}

TEST(Trajectory, ClosedLoopReturnsToTheStart) {
  TrajectorySpec spec;
  spec.frames = 40;
  spec.closed = true;
  for (int k = 0; k < 4; ++k) {
    const double a = k * M_PI / 2;
    spec.keyframes.push_back({{std::cos(a), std::sin(a), 1.0}, {0, 0, 0}});
  }
  auto poses = sampleTrajectory(spec);
  ASSERT_TRUE(poses.ok());
  // The step from the last frame back to the first is as small as the others.
  const double step = ((*poses)[1].translation() - (*poses)[0].translation()).norm();
  const double wrap = (poses->front().translation() - poses->back().translation()).norm();
  EXPECT_NEAR(wrap, step, 0.2 * step);
}

}  // namespace
}  // namespace objdb::sim
