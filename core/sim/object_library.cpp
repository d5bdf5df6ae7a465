#include "core/sim/object_library.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <utility>

#include "core/sim/shapes.h"

namespace objdb::sim {
namespace {
constexpr float kPi = 3.14159265358979f;
const Eigen::Vector3d kX = Eigen::Vector3d::UnitX();
const Eigen::Vector3d kY = Eigen::Vector3d::UnitY();

TriangleMesh ellipsoid(float ax, float ay, float az) {
  TriangleMesh m = makeSphere(1.0f, 14, 28);
  scaleMesh(&m, {ax, ay, az});
  return m;
}

TriangleMesh cow() {
  TriangleMesh m;
  addPart(&m, ellipsoid(0.36f, 0.16f, 0.17f), translation(0, 0, 0.56f));            // body
  for (float x : {-0.22f, 0.22f}) {
    for (float y : {-0.09f, 0.09f}) addPart(&m, makeCylinder(0.045f, 0.46f, 16), translation(x, y, 0));
  }
  addPart(&m, makeCylinder(0.06f, 0.2f, 16), translationRotation(0.33f, 0, 0.6f, kY, 0.9));  // neck
  addPart(&m, ellipsoid(0.13f, 0.08f, 0.09f), translation(0.47f, 0, 0.74f));        // head
  addPart(&m, ellipsoid(0.05f, 0.06f, 0.05f), translation(0.58f, 0, 0.7f));         // snout
  for (float y : {-0.05f, 0.05f}) {
    addPart(&m, makeCone(0.018f, 0.09f, 12),
            translationRotation(0.45f, y, 0.81f, Eigen::Vector3d(0, y > 0 ? -1 : 1, 0), 0.5));
    addPart(&m, ellipsoid(0.02f, 0.05f, 0.015f), translation(0.43f, y * 2.0f, 0.77f));  // ears
  }
  addPart(&m, makeCylinder(0.012f, 0.32f, 8), translationRotation(-0.35f, 0, 0.62f, kY, -2.8));
  addPart(&m, ellipsoid(0.07f, 0.05f, 0.035f), translation(0.05f, 0, 0.38f));       // udder
  return m;
}

TriangleMesh roundChair() {
  TriangleMesh m;
  addPart(&m, makeCylinder(0.25f, 0.03f), translation(0, 0, 0));                    // base
  addPart(&m, makeCylinder(0.035f, 0.42f, 16), translation(0, 0, 0.03f));           // pedestal
  addPart(&m, makeCylinder(0.23f, 0.05f), translation(0, 0, 0.43f));                // seat
  // Backrest: a half torus arc around the back (−x) plus two posts.
  addPart(&m, makeTorus(0.21f, 0.03f, kPi, 24, 10),
          translationRotation(0, 0, 0.78f, Eigen::Vector3d::UnitZ(), kPi / 2));
  for (float y : {-0.21f, 0.21f}) addPart(&m, makeCylinder(0.02f, 0.31f, 10), translation(0, y, 0.48f));
  addPart(&m, makeCylinder(0.02f, 0.31f, 10), translation(-0.21f, 0, 0.48f));
  return m;
}

TriangleMesh cubeChair() {
  TriangleMesh m;
  addPart(&m, makeBox({0.5f, 0.5f, 0.42f}), translation(0, 0, 0.21f));
  addPart(&m, makeBox({0.14f, 0.5f, 0.4f}), translation(-0.18f, 0, 0.62f));
  for (float y : {-0.22f, 0.22f}) addPart(&m, makeBox({0.36f, 0.06f, 0.16f}), translation(0.04f, y, 0.5f));
  return m;
}

TriangleMesh fireExtinguisher() {
  TriangleMesh m;
  addPart(&m, makeCylinder(0.075f, 0.42f, 24), translation(0, 0, 0));
  addPart(&m, makeSphere(0.075f, 8, 24, kPi / 2), translation(0, 0, 0.42f));
  addPart(&m, makeCylinder(0.022f, 0.08f, 12), translation(0, 0, 0.48f));
  addPart(&m, makeBox({0.14f, 0.03f, 0.018f}), translationRotation(0.03f, 0, 0.575f, kY, -0.2));
  addPart(&m, makeBox({0.12f, 0.028f, 0.015f}), translation(0.04f, 0, 0.54f));
  // Hose: from the valve down the front side.
  addPart(&m, makeCylinder(0.012f, 0.16f, 8), translationRotation(0.03f, 0, 0.53f, kY, 2.4));
  addPart(&m, makeCylinder(0.012f, 0.28f, 8), translation(0.095f, 0, 0.16f));
  addPart(&m, makeCone(0.022f, 0.05f, 10), translationRotation(0.095f, 0, 0.16f, kX, kPi));
  return m;
}

TriangleMesh gasCylinder() {
  TriangleMesh m;
  addPart(&m, makeCylinder(0.12f, 0.78f, 32), translation(0, 0, 0));
  addPart(&m, makeSphere(0.12f, 10, 32, kPi / 2), translation(0, 0, 0.78f));
  addPart(&m, makeCylinder(0.045f, 0.08f, 16), translation(0, 0, 0.88f));
  addPart(&m, makeCylinder(0.065f, 0.025f, 20), translation(0, 0, 0.96f));           // guard ring
  addPart(&m, makeBox({0.05f, 0.03f, 0.05f}), translation(0.05f, 0, 0.93f));         // valve
  addPart(&m, makeCylinder(0.125f, 0.03f, 32), translation(0, 0, 0.05f));            // foot ring
  return m;
}

TriangleMesh helmet() {
  TriangleMesh m;
  addPart(&m, makeSphere(0.13f, 10, 32, kPi / 2), translation(0, 0, 0.02f));          // shell
  addPart(&m, makeTorus(0.135f, 0.015f, 2 * kPi, 32, 8), translation(0, 0, 0.02f));  // rim
  addPart(&m, makeBox({0.06f, 0.16f, 0.015f}), translation(0.16f, 0, 0.03f));        // peak
  addPart(&m, makeBox({0.24f, 0.03f, 0.02f}), translation(0, 0, 0.15f));             // ridge
  return m;
}

TriangleMesh roundTable() {
  TriangleMesh m;
  addPart(&m, makeCylinder(0.3f, 0.03f), translation(0, 0, 0));
  addPart(&m, makeCylinder(0.05f, 0.68f, 16), translation(0, 0, 0.03f));
  addPart(&m, makeCylinder(0.45f, 0.04f, 48), translation(0, 0, 0.71f));
  return m;
}

TriangleMesh squareTable() {
  TriangleMesh m;
  addPart(&m, makeBox({0.8f, 0.8f, 0.04f}), translation(0, 0, 0.73f));
  for (float x : {-0.35f, 0.35f}) {
    for (float y : {-0.35f, 0.35f}) addPart(&m, makeBox({0.05f, 0.05f, 0.71f}), translation(x, y, 0.355f));
  }
  addPart(&m, makeBox({0.7f, 0.03f, 0.08f}), translation(0, 0.35f, 0.67f));  // apron, one side
  return m;
}

TriangleMesh largeBox() {
  TriangleMesh m;
  addPart(&m, makeBox({0.6f, 0.45f, 0.45f}), translation(0, 0, 0.225f));
  addPart(&m, makeBox({0.62f, 0.06f, 0.01f}), translation(0, 0, 0.455f));  // tape strip
  return m;
}

TriangleMesh smallContainer() {
  TriangleMesh m;
  addPart(&m, makeBox({0.3f, 0.2f, 0.16f}), translation(0, 0, 0.08f));
  addPart(&m, makeBox({0.32f, 0.22f, 0.03f}), translation(0, 0, 0.175f));   // lid
  addPart(&m, makeBox({0.1f, 0.03f, 0.03f}), translation(0, 0, 0.205f));    // handle
  return m;
}

// Kitchen kinds (the `kitchen` preset). Dimensions are those of common European kitchen and dining
// furniture: 0.6 m deep, 0.85 m high base cabinets, 0.35 m deep wall cabinets, a 0.75 m table.

TriangleMesh diningChair() {
  TriangleMesh m;
  const float leg = 0.035f, half = 0.21f - leg / 2;  // legs flush with the seat's edges
  for (float x : {-half, half}) {
    for (float y : {-half, half}) {
      addPart(&m, makeBox({leg, leg, 0.41f}), translation(x, y, 0.205f));
    }
  }
  addPart(&m, makeBox({0.42f, 0.42f, 0.04f}), translation(0, 0, 0.43f));  // seat, top at 0.45 m
  for (float y : {-half, half}) {
    addPart(&m, makeBox({leg, leg, 0.45f}), translation(-half, y, 0.675f));  // back posts
    addPart(&m, makeBox({0.35f, 0.02f, 0.02f}), translation(0, y, 0.15f));   // side stretchers
  }
  addPart(&m, makeBox({0.02f, 2 * half - leg, 0.24f}), translation(-half, 0, 0.74f));  // backrest
  return m;
}

TriangleMesh diningTable() {
  TriangleMesh m;
  addPart(&m, makeBox({1.4f, 0.8f, 0.04f}), translation(0, 0, 0.73f));  // top, 0.71–0.75 m
  // Legs and apron stand 4 cm in from the top's edges: the overhang a chair seat slides under.
  for (float x : {-0.635f, 0.635f}) {
    for (float y : {-0.335f, 0.335f}) {
      addPart(&m, makeBox({0.05f, 0.05f, 0.71f}), translation(x, y, 0.355f));
    }
  }
  for (float y : {-0.35f, 0.35f}) {
    addPart(&m, makeBox({1.22f, 0.02f, 0.08f}), translation(0, y, 0.67f));  // apron, long sides
  }
  for (float x : {-0.65f, 0.65f}) {
    addPart(&m, makeBox({0.02f, 0.62f, 0.08f}), translation(x, 0, 0.67f));  // apron, short sides
  }
  return m;
}

// Door fronts across `width` (one door below 0.55 m, two above) with 2–3 mm gaps and a bar
// handle each; `x` is the front face of the carcass, doors span z0..z1, handles at handle_z.
void addDoors(TriangleMesh* m, float width, float x, float z0, float z1, float handle_z) {
  const int doors = width < 0.55f ? 1 : 2;
  const float gap = 0.003f, door_w = (width - 0.004f - (doors - 1) * gap) / doors;
  for (int d = 0; d < doors; ++d) {
    const float y = -width / 2 + 0.002f + door_w / 2 + d * (door_w + gap);
    addPart(m, makeBox({0.02f, door_w, z1 - z0}), translation(x + 0.01f, y, (z0 + z1) / 2));
    addPart(m, makeBox({0.02f, std::min(0.16f, 0.5f * door_w), 0.012f}),
            translation(x + 0.03f, y, handle_z));
  }
}

TriangleMesh baseCabinet(float width) {
  TriangleMesh m;
  addPart(&m, makeBox({0.53f, width, 0.1f}), translation(-0.035f, 0, 0.05f));   // plinth, recessed
  addPart(&m, makeBox({0.58f, width, 0.75f}), translation(-0.01f, 0, 0.475f));  // carcass
  addDoors(&m, width, 0.28f, 0.103f, 0.847f, 0.78f);
  return m;
}

TriangleMesh wallCabinet(float width) {
  TriangleMesh m;
  addPart(&m, makeBox({0.33f, width, 0.7f}), translation(-0.01f, 0, 0.35f));
  addDoors(&m, width, 0.155f, 0.003f, 0.697f, 0.06f);
  return m;
}

TriangleMesh tallCabinet() {  // fridge-sized: 0.6 × 0.6 × 2.0 m, two stacked doors
  TriangleMesh m;
  addPart(&m, makeBox({0.53f, 0.6f, 0.1f}), translation(-0.035f, 0, 0.05f));
  addPart(&m, makeBox({0.58f, 0.6f, 1.9f}), translation(-0.01f, 0, 1.05f));
  for (auto [z0, z1] : {std::pair{0.103f, 1.197f}, std::pair{1.203f, 1.997f}}) {
    addPart(&m, makeBox({0.02f, 0.596f, z1 - z0}), translation(0.29f, 0, (z0 + z1) / 2));
  }
  for (float z : {0.95f, 1.4f}) {
    addPart(&m, makeBox({0.02f, 0.015f, 0.3f}), translation(0.31f, 0.24f, z));  // handles
  }
  return m;
}

TriangleMesh counterTop(float length) {  // 2 cm front overhang over 0.6 m deep cabinets
  TriangleMesh m;
  addPart(&m, makeBox({0.62f, length, 0.04f}), translation(0, 0, 0.02f));
  return m;
}

TriangleMesh shelf() {  // open wall shelf: a 0.8 × 0.25 m board on two brackets
  TriangleMesh m;
  addPart(&m, makeBox({0.25f, 0.8f, 0.025f}), translation(0, 0, 0.1625f));
  for (float y : {-0.3f, 0.3f}) {
    addPart(&m, makeBox({0.02f, 0.02f, 0.15f}), translation(-0.115f, y, 0.075f));  // on the wall
    addPart(&m, makeBox({0.2f, 0.02f, 0.02f}), translation(-0.025f, y, 0.14f));    // arm
  }
  return m;
}

TriangleMesh mug() {
  TriangleMesh m;
  addPart(&m, makeCylinder(0.04f, 0.1f, 24), translation(0, 0, 0));
  // Handle: a half torus in the x–z plane on the +x side, its ends on the mug's wall.
  Transform T = translation(0.04f, 0, 0.05f);
  T.linear() =
      (Eigen::AngleAxisd(kPi / 2, kX) * Eigen::AngleAxisd(-kPi / 2, Eigen::Vector3d::UnitZ()))
          .toRotationMatrix();
  addPart(&m, makeTorus(0.03f, 0.007f, kPi, 12, 8), T);
  return m;
}

TriangleMesh bowl() {  // open spherical cap, ⌀0.17 × 0.065 m, on a foot ring
  TriangleMesh m;
  addPart(&m, makeCylinder(0.035f, 0.008f, 20), translation(0, 0, 0));
  addPart(&m, makeSphere(0.09f, 8, 28, 1.2f), translationRotation(0, 0, 0.098f, kX, kPi));
  return m;
}

TriangleMesh bottle() {
  TriangleMesh m;
  addPart(&m, makeCylinder(0.035f, 0.2f, 20), translation(0, 0, 0));
  addPart(&m, makeCone(0.035f, 0.06f, 20), translation(0, 0, 0.2f));     // shoulder
  addPart(&m, makeCylinder(0.012f, 0.075f, 12), translation(0, 0, 0.23f));  // neck
  addPart(&m, makeCylinder(0.015f, 0.015f, 12), translation(0, 0, 0.3f));   // cap
  return m;
}

TriangleMesh rug(float size_x, float size_y) {
  TriangleMesh m;
  addPart(&m, makeBox({size_x, size_y, 0.01f}), translation(0, 0, 0.005f));
  return m;
}

TriangleMesh baseboard(float length) {  // 8 cm high, 1.5 cm thick, its back on the wall
  TriangleMesh m;
  addPart(&m, makeBox({0.015f, length, 0.08f}), translation(0, 0, 0.04f));
  return m;
}

}  // namespace

Rgb8 albedoIn(const std::vector<KindAlbedo>& table, const std::string& kind) {
  for (const auto& k : table) {
    if (kind == k.kind) return k.albedo;
  }
  return {180, 180, 180};
}

const std::vector<std::string>& libraryKinds() {
  static const std::vector<std::string> kinds = {
      "cow",          "round_chair", "cube_chair",  "fire_extinguisher", "gas_cylinder",
      "helmet",       "round_table", "square_table", "large_box",        "small_container",
      "floor",        "wall",
      // Kitchen kinds; base_cabinet, wall_cabinet, counter_top, rug and baseboard take a size.
      "dining_chair", "dining_table", "base_cabinet", "wall_cabinet", "tall_cabinet", "counter_top",
      "shelf",        "mug",          "bowl",         "bottle",       "rug",          "baseboard"};
  return kinds;
}

StatusOr<TriangleMesh> makeLibraryObject(const std::string& kind) {
  TriangleMesh m;
  if (kind == "cow") {
    m = cow();
  } else if (kind == "round_chair") {
    m = roundChair();
  } else if (kind == "cube_chair") {
    m = cubeChair();
  } else if (kind == "fire_extinguisher") {
    m = fireExtinguisher();
  } else if (kind == "gas_cylinder") {
    m = gasCylinder();
  } else if (kind == "helmet") {
    m = helmet();
  } else if (kind == "round_table") {
    m = roundTable();
  } else if (kind == "square_table") {
    m = squareTable();
  } else if (kind == "large_box") {
    m = largeBox();
  } else if (kind == "small_container") {
    m = smallContainer();
  } else if (kind == "floor") {
    m = makeFloor(7.0f, 5.0f);
  } else if (kind == "wall") {
    m = makeWall(1.0f, 1.0f);
  } else if (kind == "dining_chair") {
    m = diningChair();
  } else if (kind == "dining_table") {
    m = diningTable();
  } else if (kind == "tall_cabinet") {
    m = tallCabinet();
  } else if (kind == "shelf") {
    m = shelf();
  } else if (kind == "mug") {
    m = mug();
  } else if (kind == "bowl") {
    m = bowl();
  } else if (kind == "bottle") {
    m = bottle();
  } else if (sizeArity(kind) > 0) {  // sized kitchen kinds at their default size
    return makeSizedLibraryObject(kind, defaultSize(kind));
  } else {
    std::string known;
    for (const auto& k : libraryKinds()) absl::StrAppend(&known, known.empty() ? "" : ", ", k);
    return absl::InvalidArgumentError(
        absl::StrCat("unknown object kind '", kind, "' (known: ", known, ")"));
  }
  m.computeVertexNormals();
  return m;
}

int sizeArity(const std::string& kind) {
  if (kind == "floor" || kind == "wall" || kind == "rug") return 2;
  if (kind == "base_cabinet" || kind == "wall_cabinet" || kind == "counter_top" ||
      kind == "baseboard") {
    return 1;
  }
  return 0;
}

std::vector<float> defaultSize(const std::string& kind) {
  if (kind == "floor") return {7.0f, 5.0f};
  if (kind == "wall") return {1.0f, 1.0f};
  if (kind == "rug") return {2.0f, 1.4f};
  if (kind == "base_cabinet" || kind == "wall_cabinet") return {0.6f};
  if (kind == "counter_top" || kind == "baseboard") return {1.0f};
  return {};
}

StatusOr<TriangleMesh> makeSizedLibraryObject(const std::string& kind,
                                              const std::vector<float>& size) {
  static const std::map<std::string, const char*> kMeaning = {
      {"floor", "[x, y]"},        {"wall", "[length, height]"}, {"rug", "[x, y]"},
      {"base_cabinet", "[width]"}, {"wall_cabinet", "[width]"}, {"counter_top", "[length]"},
      {"baseboard", "[length]"}};
  const int arity = sizeArity(kind);
  if (arity == 0) {
    return absl::InvalidArgumentError(absl::StrCat("object kind '", kind, "' takes no size"));
  }
  if (int(size.size()) != arity) {
    return absl::InvalidArgumentError(absl::StrCat(kind, " takes size ", kMeaning.at(kind),
                                                   " (got ", size.size(), " values)"));
  }
  for (float v : size) {
    if (!(std::isfinite(v) && v > 0.0f && v < 1000.0f)) {
      return absl::InvalidArgumentError(
          absl::StrCat(kind, " size values must be in (0, 1000) metres (got ", v, ")"));
    }
  }
  TriangleMesh m;
  if (kind == "floor") {
    m = makeFloor(size[0], size[1]);
  } else if (kind == "wall") {
    m = makeWall(size[0], size[1]);
  } else if (kind == "rug") {
    m = rug(size[0], size[1]);
  } else if (kind == "base_cabinet") {
    m = baseCabinet(size[0]);
  } else if (kind == "wall_cabinet") {
    m = wallCabinet(size[0]);
  } else if (kind == "counter_top") {
    m = counterTop(size[0]);
  } else {
    m = baseboard(size[0]);
  }
  m.computeVertexNormals();
  return m;
}

TriangleMesh makeFloor(float size_x, float size_y) { return makePlane(size_x, size_y, 0.5f); }

TriangleMesh makeWall(float length, float height) {
  TriangleMesh m = makePlane(height, length, 0.5f);  // x: height, y: length, normal +z
  // Stand it up: plane normal +z → +x, plane x (height) → z.
  m.transform(translationRotation(0, 0, height / 2, Eigen::Vector3d::UnitY(), kPi / 2));
  return m;
}

void scaleMesh(TriangleMesh* mesh, const Eigen::Vector3f& scale) {
  for (auto& v : mesh->vertices) v = v.cwiseProduct(scale);
  if (!mesh->normals.empty()) mesh->computeVertexNormals();
}

}  // namespace objdb::sim
