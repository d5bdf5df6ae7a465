#include "core/sim/lounge.h"

#include <cmath>

#include "core/sim/object_library.h"

namespace objdb::sim {
namespace {
constexpr double kPi = 3.14159265358979323846;
constexpr double kRoomX = 7.0, kRoomY = 5.0, kWallHeight = 2.5;

// Albedo per kind (shared by instances of one kind, as identical objects are).
Rgb8 albedoOf(const std::string& kind) {
  static const std::vector<KindAlbedo> kinds = {
      {"cow", {235, 230, 215}},          {"round_chair", {200, 70, 45}},
      {"cube_chair", {60, 110, 180}},    {"fire_extinguisher", {210, 30, 30}},
      {"gas_cylinder", {90, 140, 90}},   {"helmet", {240, 200, 40}},
      {"round_table", {150, 110, 70}},   {"square_table", {170, 140, 100}},
      {"large_box", {190, 150, 100}},    {"small_container", {80, 80, 90}},
      {"floor", {140, 140, 135}},        {"wall", {225, 220, 210}}};
  return albedoIn(kinds, kind);
}

// One placement: instance id, kind, x, y, z (on a table top when > 0), yaw in degrees.
struct Placement {
  int id;
  const char* kind;
  double x, y, z, yaw_deg;
};

Transform at(double x, double y, double z) {
  Transform T = Transform::Identity();
  T.translation() = Eigen::Vector3d(x, y, z);
  return T;
}

SceneObject object(int id, const std::string& kind, const Transform& T, bool structure = false) {
  return makeSceneObject(id, kind, T, albedoOf(kind), structure);
}

void addRoom(Scene* scene) {
  SceneObject floor = object(17, "floor", at(kRoomX / 2, kRoomY / 2, 0), true);
  floor.size = {float(kRoomX), float(kRoomY)};
  scene->objects.push_back(floor);
  // Walls face into the room (their +x normal points inward).
  struct WallPose { double x, y, yaw, length; };
  const WallPose walls[4] = {{0, kRoomY / 2, 0, kRoomY},
                             {kRoomX, kRoomY / 2, kPi, kRoomY},
                             {kRoomX / 2, 0, kPi / 2, kRoomX},
                             {kRoomX / 2, kRoomY, -kPi / 2, kRoomX}};
  for (int i = 0; i < 4; ++i) {
    SceneObject wall = object(101 + i, "wall",
                              poseFromXyzYaw({walls[i].x, walls[i].y, 0}, walls[i].yaw), true);
    wall.size = {float(walls[i].length), float(kWallHeight)};
    scene->objects.push_back(wall);
  }
}

// Two laps around the room centre: outward (objects by the walls) then inward (central objects).
std::vector<Keyframe> loungeKeyframes(double start_deg, bool clockwise) {
  std::vector<Keyframe> keyframes;
  const Eigen::Vector3d centre(kRoomX / 2, kRoomY / 2, 0.0);
  const int steps = 18;  // keyframe every 20°
  for (int lap = 0; lap < 2; ++lap) {
    for (int k = 0; k <= steps; ++k) {
      if (lap == 1 && k == 0) continue;  // the laps share their joint keyframe
      const double a = (start_deg + (clockwise ? -1 : 1) * 360.0 * k / steps) * kPi / 180.0;
      const Eigen::Vector3d dir(std::cos(a), std::sin(a), 0.0);
      Keyframe kf;
      if (lap == 0) {
        // Outward: from a small ellipse, looking at the floor 1.6 m further out.
        kf.position = centre + Eigen::Vector3d(1.7 * dir.x(), 0.9 * dir.y(), 0.0);
        kf.position.z() = 1.45 + 0.08 * std::sin(3 * a);
        kf.look_at = kf.position + 1.6 * dir;
        kf.look_at.z() = 0.35;
      } else {
        // Inward: from a wide ellipse, looking at the middle of the room.
        kf.position = centre + Eigen::Vector3d(2.55 * dir.x(), 1.65 * dir.y(), 0.0);
        kf.position.z() = 1.55 + 0.08 * std::sin(2 * a);
        kf.look_at = centre + Eigen::Vector3d(0.35 * dir.x(), 0.25 * dir.y(), 0.45);
      }
      keyframes.push_back(kf);
    }
  }
  return keyframes;
}

Scene session(int index, const std::vector<Placement>& placements, const LoungeOptions& options,
              const Intrinsics& intrinsics, double start_deg, bool clockwise) {
  Scene scene;
  scene.name = absl::StrCat("session_", index);
  scene.camera_preset = options.camera;
  scene.intrinsics = intrinsics;
  scene.noise.enabled = options.noise;
  scene.noise.seed = options.seed + uint64_t(index);
  for (const auto& p : placements) {
    scene.objects.push_back(
        object(p.id, p.kind, poseFromXyzYaw({p.x, p.y, p.z}, p.yaw_deg * kPi / 180.0)));
  }
  addRoom(&scene);
  scene.trajectory.frames = options.frames_per_session;
  scene.trajectory.fps = 30.0;
  scene.trajectory.keyframes = loungeKeyframes(start_deg, clockwise);
  return scene;
}

}  // namespace

const std::vector<std::string>& presetNames() {
  static const std::vector<std::string> names = {"lounge", "kitchen", "two-boxes"};
  return names;
}

StatusOr<std::vector<Scene>> loungePreset(const LoungeOptions& options) {
  OBJDB_ASSIGN_OR_RETURN(Intrinsics intrinsics, intrinsicsPreset(options.camera));
  if (!(options.frames_per_session >= 40 && options.frames_per_session <= 100000)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "lounge: frames per session must be in 40..100000 (got ", options.frames_per_session, ")"));
  }
  constexpr double kTable = 0.75;  // top of both tables
  // Ids: 1 cow, 2-4 round chairs, 5 cube chair, 6-8 fire extinguishers, 9-10 gas cylinders,
  // 11-12 helmets, 13 round table, 14 square table, 15 large box, 16 small container, 17 floor.
  const std::vector<Placement> s1 = {
      {1, "cow", 4.75, 2.55, 0, 20},
      {2, "round_chair", 2.55, 2.2, 0, 10},
      {3, "round_chair", 0.9, 4.2, 0, -36},
      {4, "round_chair", 6.2, 0.8, 0, 145},
      {5, "cube_chair", 6.3, 4.2, 0, -140},
      {6, "fire_extinguisher", 0.45, 1.0, 0, 0},
      {7, "fire_extinguisher", 3.2, 4.6, 0, -90},
      {9, "gas_cylinder", 0.5, 2.6, 0, 0},
      {10, "gas_cylinder", 5.3, 4.6, 0, -90},
      {11, "helmet", 4.9, 0.75, kTable, 30},
      {13, "round_table", 3.5, 2.5, 0, 0},
      {14, "square_table", 4.9, 0.75, 0, 0},
      {15, "large_box", 2.0, 0.55, 0, 5},
      {16, "small_container", 1.6, 1.5, 0, 30}};
  const std::vector<Placement> s2 = {
      {1, "cow", 2.3, 3.3, 0, 200},
      {2, "round_chair", 2.55, 2.0, 0, 60},
      {3, "round_chair", 1.1, 0.9, 0, 40},
      {5, "cube_chair", 6.45, 2.5, 0, 180},
      {6, "fire_extinguisher", 0.45, 1.9, 0, 0},
      {7, "fire_extinguisher", 3.2, 4.6, 0, -90},
      {8, "fire_extinguisher", 6.55, 3.6, 0, 180},
      {9, "gas_cylinder", 0.5, 2.9, 0, 20},
      {11, "helmet", 3.4, 2.75, kTable, -60},
      {12, "helmet", 4.3, 1.6, 0, 45},
      {13, "round_table", 3.6, 2.6, 0, 0},
      {14, "square_table", 4.9, 0.75, 0, 15},
      {15, "large_box", 2.0, 0.6, 0, 95},
      {16, "small_container", 3.8, 2.45, kTable, 15}};
  const std::vector<Placement> s3 = {
      {1, "cow", 4.3, 3.4, 0, -60},
      {2, "round_chair", 2.45, 2.8, 0, 90},
      {4, "round_chair", 5.9, 1.2, 0, 120},
      {5, "cube_chair", 4.9, 4.45, 0, -90},
      {6, "fire_extinguisher", 3.5, 0.45, 0, 90},
      {8, "fire_extinguisher", 6.55, 3.6, 0, 180},
      {9, "gas_cylinder", 0.5, 2.6, 0, 0},
      {10, "gas_cylinder", 1.2, 4.55, 0, -90},
      {12, "helmet", 1.0, 1.0, kTable, 120},
      {13, "round_table", 3.4, 2.2, 0, 0},
      {14, "square_table", 1.0, 1.0, 0, 45},
      {15, "large_box", 6.25, 4.3, 0, 30},
      {16, "small_container", 5.3, 2.0, 0, 60}};
  return std::vector<Scene>{session(1, s1, options, intrinsics, -90.0, false),
                            session(2, s2, options, intrinsics, 0.0, true),
                            session(3, s3, options, intrinsics, 135.0, false)};
}

Scene twoBoxesScene(const std::string& camera, int frames) {
  Scene scene;
  scene.name = "two_boxes";
  scene.camera_preset = camera;
  scene.intrinsics = intrinsicsPreset(camera).value_or(Intrinsics::vga());
  scene.objects.push_back(object(1, "large_box", poseFromXyzYaw({0.0, -0.45, 0.0}, 0.3)));
  scene.objects.push_back(object(2, "small_container", poseFromXyzYaw({0.1, 0.45, 0.0}, -0.4)));
  SceneObject floor = object(3, "floor", at(0, 0, 0), true);
  floor.size = {4.0f, 4.0f};
  scene.objects.push_back(floor);
  scene.trajectory.frames = frames;
  for (double a : {-40.0, 0.0, 40.0}) {
    const double r = a * kPi / 180.0;
    scene.trajectory.keyframes.push_back(
        Keyframe{Eigen::Vector3d(-1.6 * std::cos(r), 1.6 * std::sin(r), 1.2),
                 Eigen::Vector3d(0.0, 0.0, 0.2)});
  }
  return scene;
}

}  // namespace objdb::sim
