// Procedural object library of the synthetic world: the object kinds of the paper's lounge
// (§IV: cow, round chair, cube chair, fire extinguisher, gas cylinder, helmet, round table,
// square table, large box, small container, floor) and of the kitchen preset (dining chair and
// table, cabinets, counter tops, shelf, mug, bowl, bottle, rug, baseboard) built from primitives.
// Object frame: origin at the centre of the footprint on the floor (wall-mounted kinds: at their
// bottom), z up, "front" along +x; sizes are real-world.
#pragma once

#include <string>
#include <vector>

#include "core/common/image.h"
#include "core/common/mesh.h"
#include "core/common/status.h"

namespace objdb::sim {

// A preset's colour for each kind it places (identical objects share one).
struct KindAlbedo {
  const char* kind;
  Rgb8 albedo;
};
// The albedo of `kind` in `table`; a neutral grey for a kind the table does not name.
Rgb8 albedoIn(const std::vector<KindAlbedo>& table, const std::string& kind);

// Kinds the library can build, in a fixed order.
const std::vector<std::string>& libraryKinds();

// Builds the mesh of `kind` (see libraryKinds()); an unknown kind is an error listing them.
// "floor" is a 7 × 5 m plane and "wall" a 1 × 1 m vertical plane facing +x: scale them with
// makeRoomPart instead when you need other sizes.
StatusOr<TriangleMesh> makeLibraryObject(const std::string& kind);

// How many SceneObject::size values a kind takes: 2 for floor {x, y}, wall {length, height} and
// rug {x, y}; 1 for base_cabinet {width}, wall_cabinet {width}, counter_top {length} and
// baseboard {length}; 0 for kinds of fixed size. defaultSize() is what makeLibraryObject uses.
int sizeArity(const std::string& kind);
std::vector<float> defaultSize(const std::string& kind);

// Builds a sized kind at `size` (sizeArity(kind) values, each in (0, 1000) m); an error names
// the kind and the size it takes. Widths and lengths run along the object's y axis; cabinets
// and counter tops have their back at x = −depth/2, baseboards theirs at x = −0.0075.
StatusOr<TriangleMesh> makeSizedLibraryObject(const std::string& kind,
                                              const std::vector<float>& size);

// Floor (size_x × size_y at z = 0, normal +z) or wall (length × height in the object's y–z
// plane, facing +x, bottom edge at z = 0).
TriangleMesh makeFloor(float size_x, float size_y);
TriangleMesh makeWall(float length, float height);

// Scales a mesh about its origin (normals are recomputed if present).
void scaleMesh(TriangleMesh* mesh, const Eigen::Vector3f& scale);

}  // namespace objdb::sim
