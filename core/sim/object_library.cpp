#include "core/sim/object_library.h"

#include <cmath>

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

}  // namespace

const std::vector<std::string>& libraryKinds() {
  static const std::vector<std::string> kinds = {
      "cow",          "round_chair", "cube_chair",  "fire_extinguisher", "gas_cylinder",
      "helmet",       "round_table", "square_table", "large_box",        "small_container",
      "floor",        "wall"};
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
  } else {
    std::string known;
    for (const auto& k : libraryKinds()) absl::StrAppend(&known, known.empty() ? "" : ", ", k);
    return absl::InvalidArgumentError(
        absl::StrCat("unknown object kind '", kind, "' (known: ", known, ")"));
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
