// Procedural object library of the synthetic world: the object kinds of the paper's lounge
// (§IV: cow, round chair, cube chair, fire extinguisher, gas cylinder, helmet, round table,
// square table, large box, small container, floor) built from primitives. Object frame: origin
// at the centre of the footprint on the floor, z up, "front" along +x; sizes are real-world.
#pragma once

#include <string>
#include <vector>

#include "core/common/mesh.h"
#include "core/common/status.h"

namespace objdb::sim {

// Kinds the library can build, in a fixed order.
const std::vector<std::string>& libraryKinds();

// Builds the mesh of `kind` (see libraryKinds()); an unknown kind is an error listing them.
// "floor" is a 7 × 5 m plane and "wall" a 1 × 1 m vertical plane facing +x: scale them with
// makeRoomPart instead when you need other sizes.
StatusOr<TriangleMesh> makeLibraryObject(const std::string& kind);

// Floor (size_x × size_y at z = 0, normal +z) or wall (length × height in the object's y–z
// plane, facing +x, bottom edge at z = 0).
TriangleMesh makeFloor(float size_x, float size_y);
TriangleMesh makeWall(float length, float height);

// Scales a mesh about its origin (normals are recomputed if present).
void scaleMesh(TriangleMesh* mesh, const Eigen::Vector3f& scale);

}  // namespace objdb::sim
