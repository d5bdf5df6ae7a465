#include "core/sim/kitchen.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <set>

#include <gtest/gtest.h>

#include "core/io/objdb_dataset.h"
#include "core/sim/generator.h"
#include "core/sim/lounge.h"
#include "core/sim/object_library.h"
#include "tests/support/temp_dir.h"

namespace objdb::sim {
namespace {

constexpr double kPi = 3.14159265358979323846;

bool contains(const Status& s, absl::string_view text) {
  return s.message().find(text) != absl::string_view::npos;
}

const SceneObject* find(const Scene& scene, int id) {
  for (const auto& o : scene.objects) {
    if (o.id == id) return &o;
  }
  return nullptr;
}

double angleDeg(const Eigen::Matrix3d& R) {
  return Eigen::AngleAxisd(R).angle() * 180.0 / kPi;
}

TEST(Kitchen, HasTwoSessionsWithNineObjectsAndTheFittedKitchenAsStructure) {
  auto sessions = kitchenPreset();
  ASSERT_TRUE(sessions.ok()) << sessions.status();
  ASSERT_EQ(sessions->size(), 2u);
  EXPECT_EQ((*sessions)[0].name, "session_1");
  EXPECT_EQ((*sessions)[1].name, "session_2");
  const std::set<std::string> structure_kinds = {
      "floor", "rug", "wall", "baseboard", "base_cabinet", "counter_top", "wall_cabinet",
      "shelf", "tall_cabinet"};
  std::map<int, std::string> kind_of;
  std::set<int> ids_of_session[2];
  for (size_t k = 0; k < 2; ++k) {
    const Scene& s = (*sessions)[k];
    EXPECT_TRUE(s.validate().ok()) << s.validate();
    EXPECT_EQ(s.trajectory.frames, 240);
    EXPECT_EQ(s.camera_preset, "vga");
    EXPECT_EQ(s.intrinsics, Intrinsics::vga());
    for (const auto& o : s.objects) {
      ids_of_session[k].insert(o.id);
      EXPECT_EQ(o.structure, structure_kinds.count(o.category) == 1) << "id " << o.id;
      auto [it, inserted] = kind_of.emplace(o.id, o.category);
      EXPECT_EQ(it->second, o.category) << "id " << o.id << " changes kind between sessions";
    }
  }
  EXPECT_EQ(ids_of_session[0], ids_of_session[1]);  // nothing leaves or arrives
  std::map<std::string, std::set<int>> ids_of;
  for (const auto& [id, kind] : kind_of) ids_of[kind].insert(id);
  const std::map<std::string, std::set<int>> expected = {
      {"dining_table", {1}},
      {"dining_chair", {2, 3, 4, 5}},
      {"mug", {6, 7}},
      {"bowl", {8}},
      {"bottle", {9}},
      {"floor", {20}},
      {"rug", {21}},
      {"base_cabinet", {30, 31, 32, 33, 34, 35, 36}},
      {"counter_top", {40, 41}},
      {"tall_cabinet", {42}},
      {"wall_cabinet", {43, 44, 45}},
      {"shelf", {46}},
      {"wall", {101, 102, 103, 104, 105, 106}},
      {"baseboard", {111, 112, 113, 114, 115, 116}}};
  EXPECT_EQ(ids_of, expected);
  // The four chairs are identical: one mesh, one albedo, no size or scale of their own.
  const Scene& s1 = (*sessions)[0];
  const SceneObject* first = find(s1, 2);
  ASSERT_NE(first, nullptr);
  for (int id : {3, 4, 5}) {
    const SceneObject* chair = find(s1, id);
    ASSERT_NE(chair, nullptr);
    EXPECT_EQ(chair->mesh, "dining_chair");
    EXPECT_EQ(chair->mesh, first->mesh);
    EXPECT_EQ(chair->albedo, first->albedo);
    EXPECT_EQ(chair->scale, first->scale);
    EXPECT_TRUE(chair->size.empty());
  }
}

TEST(Kitchen, ChairsAreTuckedInWithTheSeatFrontUnderTheTableTopsEdge) {
  auto sessions = kitchenPreset();
  ASSERT_TRUE(sessions.ok());
  const Scene& s1 = (*sessions)[0];
  auto chair_mesh = makeLibraryObject("dining_chair");
  auto table_mesh = makeLibraryObject("dining_table");
  ASSERT_TRUE(chair_mesh.ok() && table_mesh.ok());
  Eigen::Vector3f chair_lo, chair_hi, table_lo, table_hi;
  ASSERT_TRUE(chair_mesh->bounds(&chair_lo, &chair_hi));
  ASSERT_TRUE(table_mesh->bounds(&table_lo, &table_hi));
  // The chair's front (+x) is its seat's front edge; the highest point within 5 cm of it is the
  // seat top. The table top's underside: the lowest point outside the apron (|y| > 0.38 m).
  float seat_top = 0.0f;
  for (const auto& v : chair_mesh->vertices) {
    if (v.x() > chair_hi.x() - 0.05f) seat_top = std::max(seat_top, v.z());
  }
  float underside = table_hi.z();
  for (const auto& v : table_mesh->vertices) {
    if (std::abs(v.y()) > 0.38f) underside = std::min(underside, v.z());
  }
  EXPECT_NEAR(seat_top, 0.45f, 1e-5f);
  EXPECT_NEAR(underside, 0.71f, 1e-5f);
  EXPECT_NEAR(table_hi.y(), 0.4f, 1e-5f);
  const SceneObject* table = find(s1, 1);
  ASSERT_NE(table, nullptr);
  const Transform T_table_world = table->T_world_object.inverse();
  std::map<int, int> side_count;  // table side (+1 / −1 in y) → chairs
  for (int id : {2, 3, 4, 5}) {
    const SceneObject* chair = find(s1, id);
    ASSERT_NE(chair, nullptr);
    const Transform T_table_chair = T_table_world * chair->T_world_object;
    // Both front corners of the seat, in the table frame.
    for (float y : {chair_lo.y(), chair_hi.y()}) {
      const Eigen::Vector3d corner =
          T_table_chair * Eigen::Vector3d(chair_hi.x(), y, seat_top);
      const double inset = table_hi.y() - std::abs(corner.y());  // > 0: under the top
      EXPECT_GE(inset, 0.0) << "chair " << id << " does not reach the table's edge";
      EXPECT_LE(inset, 0.01) << "chair " << id << " is " << inset << " m under the top";
      EXPECT_LT(std::abs(corner.x()), table_hi.x()) << "chair " << id;
      EXPECT_LT(corner.z(), underside) << "chair " << id << "'s seat hits the top";
    }
    // The chair faces the table: its front points across the table's long axis, inwards.
    const Eigen::Vector3d forward = T_table_chair.linear().col(0);
    const double side = T_table_chair.translation().y() > 0 ? 1.0 : -1.0;
    EXPECT_NEAR(forward.y(), -side, 1e-9) << "chair " << id;
    ++side_count[int(side)];
  }
  EXPECT_EQ(side_count, (std::map<int, int>{{-1, 2}, {1, 2}}));  // two on each long side
}

TEST(Kitchen, CabinetsStandFlushAgainstTheWallsAndEachOther) {
  auto sessions = kitchenPreset();
  ASSERT_TRUE(sessions.ok());
  const Scene& s = (*sessions)[0];
  std::vector<const SceneObject*> walls, cabinets;
  for (const auto& o : s.objects) {
    if (o.category == "wall") walls.push_back(&o);
    if (o.category == "base_cabinet" || o.category == "tall_cabinet") cabinets.push_back(&o);
  }
  ASSERT_EQ(cabinets.size(), 8u);
  // Cabinets are 0.6 m deep with their origin at the footprint's centre: the back is at x = −0.3.
  auto width = [](const SceneObject* c) { return c->size.empty() ? 0.6 : double(c->size[0]); };
  for (const auto* c : cabinets) {
    const Eigen::Vector3d back = c->T_world_object * Eigen::Vector3d(-0.3, 0, 0.4);
    double best = 1e9;
    for (const auto* w : walls) {
      const Eigen::Vector3d local = w->T_world_object.inverse() * back;
      if (std::abs(local.y()) <= w->size[0] / 2) best = std::min(best, std::abs(local.x()));
    }
    EXPECT_LT(best, 1e-9) << "cabinet " << c->id << " stands " << best << " m off the wall";
    int touching = 0;
    for (const auto* other : cabinets) {
      if (other == c) continue;
      for (double sa : {-0.5, 0.5}) {
        for (double sb : {-0.5, 0.5}) {
          const Eigen::Vector3d a = c->T_world_object * Eigen::Vector3d(0, sa * width(c), 0.4);
          const Eigen::Vector3d b =
              other->T_world_object * Eigen::Vector3d(0, sb * width(other), 0.4);
          touching += (a - b).norm() < 1e-6;  // sizes are stored as floats
        }
      }
    }
    EXPECT_GE(touching, 1) << "cabinet " << c->id << " touches no other cabinet";
  }
}

TEST(Kitchen, LongWallsAreTwoPiecesMeetingAtAShallowAngle) {
  auto sessions = kitchenPreset();
  ASSERT_TRUE(sessions.ok());
  const Scene& s = (*sessions)[0];
  for (auto [a, b] : {std::pair{102, 103}, std::pair{105, 106}}) {
    const SceneObject* wa = find(s, a);
    const SceneObject* wb = find(s, b);
    ASSERT_TRUE(wa && wb);
    const Eigen::Vector3d na = wa->T_world_object.linear().col(0);
    const Eigen::Vector3d nb = wb->T_world_object.linear().col(0);
    const double deg = std::acos(std::clamp(na.dot(nb), -1.0, 1.0)) * 180.0 / kPi;
    EXPECT_GE(deg, 1.0) << a << "/" << b;
    EXPECT_LE(deg, 2.0) << a << "/" << b;
  }
}

TEST(Kitchen, SessionTwoMovesTwoChairsAndAMug) {
  auto sessions = kitchenPreset();
  ASSERT_TRUE(sessions.ok());
  const Scene& a = (*sessions)[0];
  const Scene& b = (*sessions)[1];
  std::set<int> moved;
  for (const auto& o : a.objects) {
    const SceneObject* other = find(b, o.id);
    ASSERT_NE(other, nullptr);
    if (!o.T_world_object.isApprox(other->T_world_object, 1e-9)) moved.insert(o.id);
  }
  EXPECT_EQ(moved, (std::set<int>{2, 5, 7}));
  // Chair 5 stands by the right wall (x = 5 m), turned round; mug 7 went onto the table.
  EXPECT_GT(find(b, 5)->T_world_object.translation().x(), 4.6);
  EXPECT_NEAR(find(b, 7)->T_world_object.translation().z(), 0.76, 1e-9);
  EXPECT_GT(find(a, 7)->T_world_object.translation().z(), 0.85);
}

TEST(Kitchen, DriftGrowsSmoothlyFromZeroAndIsOffWhenDisabled) {
  auto sessions = kitchenPreset();
  ASSERT_TRUE(sessions.ok());
  const Scene& s = (*sessions)[0];
  ASSERT_TRUE(s.drift.enabled());
  auto poses = sampleTrajectory(s.trajectory);
  ASSERT_TRUE(poses.ok());
  const size_t n = poses->size();
  Eigen::Vector3d previous = Eigen::Vector3d::Zero();
  double max_step = 0.0;
  for (size_t i = 0; i < n; ++i) {
    const Transform T = driftedPose(s.drift, (*poses)[i], i, n);
    const Eigen::Vector3d dt = T.translation() - (*poses)[i].translation();
    const double drot = angleDeg(T.linear() * (*poses)[i].linear().transpose());
    if (i == 0) {
      EXPECT_TRUE(T.matrix() == (*poses)[0].matrix()) << "frame 0 drifts";
    }
    EXPECT_LE(dt.norm(), 0.025 + 1e-6) << "frame " << i;
    EXPECT_LE(drot, 0.4 + 1e-6) << "frame " << i;
    max_step = std::max(max_step, (dt - previous).norm());
    previous = dt;
  }
  // At the last frame: between 0.7 and 1 of the amplitudes (2.5 cm, 0.4°).
  const Transform last = driftedPose(s.drift, poses->back(), n - 1, n);
  const double t_last = (last.translation() - poses->back().translation()).norm();
  const double r_last = angleDeg(last.linear() * poses->back().linear().transpose());
  EXPECT_GE(t_last, 0.0175);
  EXPECT_LE(t_last, 0.025 + 1e-6);
  EXPECT_GE(r_last, 0.28);
  EXPECT_LE(r_last, 0.4 + 1e-6);
  EXPECT_LT(max_step, 0.001);  // smooth: under a millimetre per frame

  KitchenOptions off;
  off.drift = false;
  auto still = kitchenPreset(off);
  ASSERT_TRUE(still.ok());
  EXPECT_FALSE((*still)[0].drift.enabled());
  EXPECT_TRUE(driftedPose((*still)[0].drift, poses->back(), n - 1, n).isApprox(poses->back(), 0));
}

TEST(Kitchen, DatasetPosesDriftButInstancesShowTheTrueView) {
  testing::TempDir dir;
  auto sessions = kitchenPreset();
  ASSERT_TRUE(sessions.ok());
  Scene scene = (*sessions)[0];
  // Two small frames: frame 1 is the end of the (cut) trajectory, with the full drift.
  scene.camera_preset = "tango";
  scene.intrinsics = Intrinsics::tango();
  scene.noise.enabled = false;
  scene.trajectory.frames = 2;
  GenerateOptions options;
  options.write_color = false;
  auto stats = generateDataset(scene, dir / "kitchen", options);
  ASSERT_TRUE(stats.ok()) << stats.status();
  auto dataset = io::ObjdbDataset::open(dir / "kitchen");
  ASSERT_TRUE(dataset.ok()) << dataset.status();
  ASSERT_EQ((*dataset)->size(), 2u);
  auto poses = sampleTrajectory(scene.trajectory);
  ASSERT_TRUE(poses.ok());
  auto f0 = (*dataset)->loadFrame(0);
  auto f1 = (*dataset)->loadFrame(1);
  ASSERT_TRUE(f0.ok() && f1.ok());
  EXPECT_LT((f0->T_world_camera.translation() - (*poses)[0].translation()).norm(), 1e-6);
  const double moved = (f1->T_world_camera.translation() - (*poses)[1].translation()).norm();
  EXPECT_GE(moved, 0.005);
  EXPECT_LE(moved, 0.04);
  EXPECT_TRUE(f1->T_world_camera.isApprox(driftedPose(scene.drift, (*poses)[1], 1, 2), 1e-6));
  // The ground-truth instances describe the image: rendered from the true pose.
  auto built = buildScene(scene);
  ASSERT_TRUE(built.ok());
  RenderParams params;
  params.render_color = false;
  RenderOutput truth;
  Renderer(scene.intrinsics, params).render(built->instances, (*poses)[1], &truth);
  ASSERT_TRUE(f1->instances.has_value());
  EXPECT_EQ(*f1->instances, truth.instances);
  EXPECT_GT(stats->frames_visible.at(1) + stats->frames_visible.at(2), 0);  // sees the table
}

TEST(Kitchen, NoiseQuantisesDisparityWhileTheLoungeKeepsItsDefaults) {
  auto kitchen = kitchenPreset();
  auto lounge = loungePreset();
  ASSERT_TRUE(kitchen.ok() && lounge.ok());
  EXPECT_TRUE((*kitchen)[0].noise.enabled);
  EXPECT_GT((*kitchen)[0].noise.disparity_quantum, 0.002f);
  EXPECT_LT((*kitchen)[0].noise.disparity_quantum, 0.004f);
  EXPECT_NE((*kitchen)[0].noise.seed, (*kitchen)[1].noise.seed);
  for (const auto& s : *lounge) {
    EXPECT_EQ(s.noise.disparity_quantum, 0.0f);
    EXPECT_FALSE(s.drift.enabled());
    // The scene files the lounge writes are those from before the new fields.
    const std::string json = sceneToJson(s);
    EXPECT_EQ(json.find("disparity_quantum"), std::string::npos);
    EXPECT_EQ(json.find("drift"), std::string::npos);
  }
  KitchenOptions quiet;
  quiet.noise = false;
  auto exact = kitchenPreset(quiet);
  ASSERT_TRUE(exact.ok());
  EXPECT_FALSE((*exact)[0].noise.enabled);
}

TEST(Kitchen, SceneJsonRoundTripKeepsDriftNoiseAndSizes) {
  auto sessions = kitchenPreset();
  ASSERT_TRUE(sessions.ok());
  const Scene& scene = (*sessions)[1];
  auto parsed = parseSceneJson(sceneToJson(scene), ".");
  ASSERT_TRUE(parsed.ok()) << parsed.status();
  EXPECT_FLOAT_EQ(parsed->drift.translation_m, scene.drift.translation_m);
  EXPECT_FLOAT_EQ(parsed->drift.rotation_deg, scene.drift.rotation_deg);
  EXPECT_EQ(parsed->drift.seed, scene.drift.seed);
  EXPECT_FLOAT_EQ(parsed->noise.disparity_quantum, scene.noise.disparity_quantum);
  ASSERT_EQ(parsed->objects.size(), scene.objects.size());
  for (size_t i = 0; i < scene.objects.size(); ++i) {
    EXPECT_EQ(parsed->objects[i].size, scene.objects[i].size) << scene.objects[i].id;
    EXPECT_EQ(parsed->objects[i].structure, scene.objects[i].structure);
  }
  auto a = buildScene(scene);
  auto b = buildScene(*parsed);
  ASSERT_TRUE(a.ok()) << a.status();
  ASSERT_TRUE(b.ok()) << b.status();
  EXPECT_EQ(trueSurface(*a).triangles.size(), trueSurface(*b).triangles.size());
}

TEST(Kitchen, BadOptionsAndBadDriftGiveErrorsNamingTheValue) {
  for (int frames : {39, 100001}) {
    KitchenOptions options;
    options.frames_per_session = frames;
    auto sessions = kitchenPreset(options);
    ASSERT_FALSE(sessions.ok()) << frames;
    EXPECT_EQ(sessions.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_TRUE(contains(sessions.status(), absl::StrCat("got ", frames)))
        << sessions.status().message();
  }
  KitchenOptions camera;
  camera.camera = "kinect2";
  EXPECT_FALSE(kitchenPreset(camera).ok());

  const std::string traj = R"("trajectory": {"keyframes": [{"position": [0,0,1], "look_at": [1,0,0]},
                                                           {"position": [0,1,1], "look_at": [1,0,0]}]})";
  struct Case {
    std::string json, expected;
  } cases[] = {
      {R"({"drift": {"translation_m": -0.01}, )" + traj + "}", "drift.translation_m"},
      {R"({"drift": {"rotation_deg": 20}, )" + traj + "}", "drift.rotation_deg"},
      {R"({"drift": {"translation_m": "2cm"}, )" + traj + "}", "drift.translation_m"},
      {R"({"drift": {"yaw_deg": 1}, )" + traj + "}", "unknown key 'yaw_deg'"},
      {R"({"drift": {"seed": -1}, )" + traj + "}", "drift.seed"},
      {R"({"noise": {"disparity_quantum": -0.1}, )" + traj + "}", "disparity_quantum"},
      {R"({"objects": [{"id": 1, "category": "rug", "size": [1, 2, 3]}], )" + traj + "}",
       "objects[0].size"},
  };
  for (const auto& c : cases) {
    auto scene = parseSceneJson(c.json, ".");
    ASSERT_FALSE(scene.ok()) << c.json;
    EXPECT_TRUE(contains(scene.status(), c.expected))
        << "expected '" << c.expected << "' in: " << scene.status().message();
  }
  // A sized kind given the wrong number of sizes is named when building.
  auto sessions = kitchenPreset();
  ASSERT_TRUE(sessions.ok());
  Scene scene = (*sessions)[0];
  for (auto& o : scene.objects) {
    if (o.id == 30) o.size = {0.6f, 0.85f};
  }
  auto built = buildScene(scene);
  ASSERT_FALSE(built.ok());
  EXPECT_TRUE(contains(built.status(), "object 30"));
  EXPECT_TRUE(contains(built.status(), "base_cabinet takes size [width]"));
}

}  // namespace
}  // namespace objdb::sim
