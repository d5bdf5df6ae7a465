#include "core/sim/kitchen.h"

#include <cmath>

#include "core/sim/object_library.h"

namespace objdb::sim {
namespace {
constexpr double kPi = 3.14159265358979323846;
constexpr double kWallHeight = 2.5;
constexpr double kBendDeg = 1.5;        // angle between the two pieces of a long wall
constexpr double kCabinetDepth = 0.6;   // base and tall cabinets (object_library.cpp)
constexpr double kCounterDepth = 0.62;  // counter tops: 2 cm front overhang
constexpr double kCounterZ = 0.85;      // underside of the counter tops = top of the cabinets
constexpr double kCounterTop = kCounterZ + 0.04;  // where items on the counter stand
constexpr double kRugTop = 0.01;                   // table and chairs on the rug stand on it
constexpr double kTableTop = kRugTop + 0.75;       // dining_table's top
// Sensor model of the preset: a Kinect-like structured-light camera, disparity step 1/8 pixel at
// f = 580 px, baseline 7.5 cm (Khoshelham & Oude Elberink 2012): depth step ≈ 0.0028 · z².
constexpr float kDisparityQuantum = 0.0028f;
// Pose drift at the end of a session: what a visual-inertial tracker accumulates over a ~20 m
// walk (centimetres, a fraction of a degree, mostly yaw).
constexpr float kDriftTranslationM = 0.025f;
constexpr float kDriftRotationDeg = 0.4f;

// Albedo per kind (shared by instances of one kind, as identical objects are).
Rgb8 albedoOf(const std::string& kind) {
  static const std::vector<KindAlbedo> kinds = {
      {"dining_chair", {125, 85, 55}},   {"dining_table", {165, 125, 85}},
      {"mug", {40, 90, 160}},            {"bowl", {225, 205, 165}},
      {"bottle", {40, 120, 60}},         {"base_cabinet", {235, 233, 226}},
      {"wall_cabinet", {235, 233, 226}}, {"tall_cabinet", {205, 205, 210}},
      {"counter_top", {75, 72, 70}},     {"shelf", {175, 135, 95}},
      {"rug", {150, 65, 50}},            {"baseboard", {245, 244, 238}},
      {"floor", {185, 165, 135}},        {"wall", {228, 224, 214}}};
  return albedoIn(kinds, kind);
}

SceneObject object(int id, const std::string& kind, const Transform& T, bool structure,
                   std::vector<float> size = {}) {
  return makeSceneObject(id, kind, T, albedoOf(kind), structure, std::move(size));
}

// A straight piece of wall along the floor from p to q.
struct Segment {
  Eigen::Vector2d p, q;
  double length() const { return (q - p).norm(); }
  Eigen::Vector2d direction() const { return (q - p).normalized(); }
  // The wall's normal pointing into the room (towards its centre).
  Eigen::Vector2d inward() const {
    const Eigen::Vector2d d = direction();
    const Eigen::Vector2d n(d.y(), -d.x());
    return n.dot(Eigen::Vector2d(2.5, 2.0) - (p + q) / 2) > 0 ? n : Eigen::Vector2d(-n);
  }
};

// Pose of something standing against `wall`: its object x axis along the inward normal, its
// origin `along` metres from p and `offset` metres in front of the wall, at height z.
Transform againstWall(const Segment& wall, double along, double offset, double z) {
  const Eigen::Vector2d n = wall.inward();
  const Eigen::Vector2d c = wall.p + along * wall.direction() + offset * n;
  return poseFromXyzYaw({c.x(), c.y(), z}, std::atan2(n.y(), n.x()));
}

// The room's wall pieces. The long walls (y = 0 and y = 4) are each two pieces meeting at
// kBendDeg: the front wall bends inwards at x = 2.2, the back wall outwards at x = 3.2, so the
// room is not a perfect box; the back wall's left piece and the left wall are straight, so the
// fitted cabinets stand flush against them.
struct Room {
  Segment left, front_a, front_b, right, back_a, back_b;
};
Room room() {
  const double bend = std::tan(kBendDeg * kPi / 180.0);
  const Eigen::Vector2d front_joint(2.2, 0.0), back_joint(3.2, 4.0);
  const Eigen::Vector2d front_right(5.0, 2.8 * bend), back_right(5.0, 4.0 + 1.8 * bend);
  return Room{{{0.0, 0.0}, {0.0, 4.0}},       {{0.0, 0.0}, front_joint},
              {front_joint, front_right},     {front_right, back_right},
              {{0.0, 4.0}, back_joint},       {back_joint, back_right}};
}

// A wall piece extended by `extend_p` / `extend_q` past its ends: 2 cm into the corners, 5 mm
// past a bend (at 1.5° the overlap stands 0.13 mm off the other piece), so no crack shows.
SceneObject wallPiece(int id, const Segment& s, double extend_p, double extend_q) {
  const double length = s.length() + extend_p + extend_q;
  return object(id, "wall", againstWall(s, (s.length() + extend_q - extend_p) / 2, 0.0, 0.0), true,
                {float(length), float(kWallHeight)});
}

SceneObject baseboard(int id, const Segment& s, double from, double to) {
  return object(id, "baseboard", againstWall(s, (from + to) / 2, 0.0075, 0.0), true,
                {float(to - from)});
}

// Floor, rug, walls, baseboards and the fitted kitchen: the structure, the same in both sessions.
void addKitchen(Scene* scene) {
  const Room r = room();
  auto add = [&](SceneObject o) { scene->objects.push_back(std::move(o)); };
  // The floor reaches 0.2 m under the walls, so the bent pieces never show its edge.
  add(object(20, "floor", poseFromXyzYaw({2.5, 2.0, 0.0}, 0.0), true, {5.4f, 4.4f}));
  add(object(21, "rug", poseFromXyzYaw({3.3, 1.7, 0.0}, 0.0), true, {2.4f, 2.4f}));
  add(wallPiece(101, r.left, 0.02, 0.02));
  add(wallPiece(102, r.front_a, 0.02, 0.005));
  add(wallPiece(103, r.front_b, 0.005, 0.02));
  add(wallPiece(104, r.right, 0.02, 0.02));
  add(wallPiece(105, r.back_a, 0.02, 0.005));
  add(wallPiece(106, r.back_b, 0.005, 0.02));
  // Base cabinets, backs on the walls and sides touching. Back run (x from the left wall):
  // the corner unit 0–0.6, then 0.6–1.4, 1.4–1.8, 1.8–2.4. Left run (y from the front wall):
  // 2.78–3.38, 2.28–2.78, 1.78–2.28; it stops 2 cm short of the corner unit's door front, where
  // the door handles touch its side (the blind corner's filler gap).
  struct Run {
    int id;
    const Segment* wall;
    double from, to;
  };
  const Run base[] = {{30, &r.back_a, 0.0, 0.6},  {31, &r.back_a, 0.6, 1.4},
                      {32, &r.back_a, 1.4, 1.8},  {33, &r.back_a, 1.8, 2.4},
                      {34, &r.left, 2.78, 3.38},  {35, &r.left, 2.28, 2.78},
                      {36, &r.left, 1.78, 2.28}};
  for (const auto& c : base) {
    add(object(c.id, "base_cabinet",
               againstWall(*c.wall, (c.from + c.to) / 2, kCabinetDepth / 2, 0.0), true,
               {float(c.to - c.from)}));
  }
  // Counter tops: the back one covers the corner, the left one butts against its front edge and
  // overhangs the end of the left run by 2 cm.
  const Run counters[] = {{40, &r.back_a, 0.0, 2.4}, {41, &r.left, 1.76, 4.0 - kCounterDepth}};
  for (const auto& c : counters) {
    add(object(c.id, "counter_top",
               againstWall(*c.wall, (c.from + c.to) / 2, kCounterDepth / 2, kCounterZ), true,
               {float(c.to - c.from)}));
  }
  // The fridge-sized tall cabinet ends the back run; wall cabinets (bottom at 1.45 m)
  // hang over the back run.
  add(object(42, "tall_cabinet", againstWall(r.back_a, 2.7, kCabinetDepth / 2, 0), true));
  for (int k = 0; k < 3; ++k) {
    add(object(43 + k, "wall_cabinet", againstWall(r.back_a, 0.4 + 0.8 * k, 0.175, 1.45), true,
               {0.8f}));
  }
  add(object(46, "shelf", againstWall(r.left, 2.58, 0.125, 1.5), true));  // over the left run
  // Baseboards along the free length of every wall piece (none behind cabinets); the left and
  // right ones start 1.5 cm from the corners, where the front and back ones end.
  add(baseboard(111, r.left, 0.015, 1.78));
  add(baseboard(112, r.front_a, 0.0, r.front_a.length()));
  add(baseboard(113, r.front_b, 0.0, r.front_b.length()));
  add(baseboard(114, r.right, 0.015, r.right.length() - 0.015));
  add(baseboard(115, r.back_a, 3.0, r.back_a.length()));
  add(baseboard(116, r.back_b, 0.0, r.back_b.length()));
}

// One placement: instance id, kind, x, y, z (on the counter or the table when > 0), yaw in
// degrees (the kind's front, +x, turned from world +x).
struct Placement {
  int id;
  const char* kind;
  double x, y, z, yaw_deg;
};

// A walk through the kitchen: camera centre and look-at point per keyframe.
struct Waypoint {
  double px, py, pz, lx, ly, lz;
};

std::vector<Keyframe> keyframes(const std::vector<Waypoint>& waypoints) {
  std::vector<Keyframe> out;
  for (const auto& w : waypoints) {
    out.push_back(Keyframe{Eigen::Vector3d(w.px, w.py, w.pz), Eigen::Vector3d(w.lx, w.ly, w.lz)});
  }
  return out;
}

// Session 1: from the doorway (front left) along the left run (bowl), the back counter (mugs,
// bottle), behind the chairs, round the table's right end and back along the front to the mugs;
// session 2 starts at the front right and goes the other way round, so both sides of everything
// are seen across the sessions. The camera stays 1.45–1.6 m high and looks down at the counter
// (0.9 m), the table and the seats (0.45–0.6 m): the floor is mostly hidden by furniture, and
// counter items are seen from 0.8–1.2 m.
std::vector<Keyframe> kitchenKeyframes(int session) {
  if (session == 1) {
    return keyframes({{1.2, 0.6, 1.55, 0.4, 2.6, 0.9},
                      {1.0, 2.1, 1.5, 0.3, 2.6, 0.9},
                      {0.95, 2.45, 1.5, 0.35, 2.5, 0.9},
                      {1.2, 2.75, 1.5, 0.9, 3.55, 0.9},
                      {1.7, 2.85, 1.5, 1.3, 3.55, 0.9},
                      {2.3, 2.85, 1.5, 2.0, 3.55, 0.95},
                      {2.55, 2.8, 1.5, 2.05, 3.5, 1.0},
                      {2.8, 2.95, 1.6, 3.3, 1.7, 0.55},
                      {4.0, 2.95, 1.55, 3.3, 1.7, 0.5},
                      {4.6, 2.2, 1.5, 3.2, 1.7, 0.5},
                      {4.6, 0.6, 1.5, 3.3, 1.8, 0.5},
                      {3.3, 0.45, 1.55, 3.3, 1.9, 0.45},
                      {2.0, 0.5, 1.5, 3.2, 1.9, 0.5},
                      {1.5, 1.4, 1.55, 3.1, 1.7, 0.6},
                      {1.6, 2.6, 1.5, 1.1, 3.55, 0.9},
                      {2.1, 2.8, 1.45, 3.3, 1.6, 0.5}});
  }
  return keyframes({{4.5, 0.5, 1.5, 3.3, 1.8, 0.5},
                    {3.0, 0.45, 1.55, 3.0, 2.0, 0.5},
                    {1.6, 0.6, 1.5, 3.0, 1.9, 0.55},
                    {1.3, 1.5, 1.55, 0.35, 2.5, 0.9},
                    {1.0, 2.05, 1.5, 0.3, 2.6, 0.9},
                    {1.1, 2.5, 1.5, 0.6, 3.3, 0.9},
                    {1.4, 2.85, 1.5, 1.1, 3.55, 0.9},
                    {2.0, 2.8, 1.5, 2.05, 3.55, 0.95},
                    {2.5, 2.85, 1.5, 2.0, 3.5, 1.0},
                    {3.2, 2.95, 1.55, 3.3, 1.7, 0.5},
                    {4.2, 2.95, 1.5, 4.7, 2.9, 0.45},
                    {4.55, 1.9, 1.55, 3.2, 1.6, 0.5},
                    {4.3, 0.7, 1.5, 4.7, 2.9, 0.5},
                    {3.0, 0.5, 1.5, 3.3, 1.7, 0.5}});
}

Scene session(int index, const std::vector<Placement>& placements, const KitchenOptions& options,
              const Intrinsics& intrinsics) {
  Scene scene;
  scene.name = absl::StrCat("session_", index);
  scene.camera_preset = options.camera;
  scene.intrinsics = intrinsics;
  scene.noise.enabled = options.noise;
  scene.noise.seed = options.seed + uint64_t(index);
  scene.noise.disparity_quantum = kDisparityQuantum;
  if (options.drift) {
    scene.drift.translation_m = kDriftTranslationM;
    scene.drift.rotation_deg = kDriftRotationDeg;
    scene.drift.seed = options.seed + uint64_t(index);
  }
  for (const auto& p : placements) {
    scene.objects.push_back(object(
        p.id, p.kind, poseFromXyzYaw({p.x, p.y, p.z}, p.yaw_deg * kPi / 180.0), false));
  }
  addKitchen(&scene);
  scene.trajectory.frames = options.frames_per_session;
  scene.trajectory.fps = 30.0;
  scene.trajectory.keyframes = kitchenKeyframes(index);
  return scene;
}

}  // namespace

StatusOr<std::vector<Scene>> kitchenPreset(const KitchenOptions& options) {
  OBJDB_ASSIGN_OR_RETURN(Intrinsics intrinsics, intrinsicsPreset(options.camera));
  if (!(options.frames_per_session >= 40 && options.frames_per_session <= 100000)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "kitchen: frames per session must be in 40..100000 (got ", options.frames_per_session,
        ")"));
  }
  // The table stands on the rug at (3.3, 1.7), long side along x, its top 1.4 × 0.8 m. Chairs
  // tucked in: a chair's origin is its seat centre and its seat front 0.21 m ahead, so a chair
  // 0.605 m from the table's axis has its seat front 5 mm inside the top's edge — under the
  // overhang, 3.5 cm short of the apron. Mugs and bottle stand in front of the wall cabinets.
  constexpr double kTx = 3.3, kTy = 1.7, kTuck = 0.4 - 0.005 + 0.21;
  const std::vector<Placement> s1 = {
      {1, "dining_table", kTx, kTy, kRugTop, 0},
      {2, "dining_chair", kTx - 0.35, kTy + kTuck, kRugTop, -90},
      {3, "dining_chair", kTx + 0.35, kTy + kTuck, kRugTop, -90},
      {4, "dining_chair", kTx - 0.35, kTy - kTuck, kRugTop, 90},
      {5, "dining_chair", kTx + 0.35, kTy - kTuck, kRugTop, 90},
      {6, "mug", 1.05, 3.55, kCounterTop, 200},
      {7, "mug", 1.3, 3.57, kCounterTop, 120},
      {8, "bowl", 0.32, 2.55, kCounterTop, 0},
      {9, "bottle", 2.05, 3.55, kCounterTop, 0}};
  // Session 2: chair 2 pulled out (still on the rug) and turned, chair 5 against the right wall
  // (off the rug), chairs 3 and 4 still tucked in; mug 7 moved from the counter to the table.
  const std::vector<Placement> s2 = {
      {1, "dining_table", kTx, kTy, kRugTop, 0},
      {2, "dining_chair", 2.75, 2.55, kRugTop, -50},
      {3, "dining_chair", kTx + 0.35, kTy + kTuck, kRugTop, -90},
      {4, "dining_chair", kTx - 0.35, kTy - kTuck, kRugTop, 90},
      {5, "dining_chair", 4.73, 2.9, 0, 180},
      {6, "mug", 1.05, 3.55, kCounterTop, 200},
      {7, "mug", 3.45, 1.55, kTableTop, 30},
      {8, "bowl", 0.32, 2.55, kCounterTop, 0},
      {9, "bottle", 2.05, 3.55, kCounterTop, 0}};
  return std::vector<Scene>{session(1, s1, options, intrinsics),
                            session(2, s2, options, intrinsics)};
}

}  // namespace objdb::sim
