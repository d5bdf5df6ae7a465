// Room structure for a whole map (ours; the paper leaves structure to the planarity test of
// §III-C.1). Floors, walls, ceilings and the big built-in faces (cabinet fronts, counter tops,
// partitions) are found once per map from its fused surface, not from one GSM label: the
// segmenter cuts a real floor into pieces smaller than any size rule, so a label alone cannot
// tell a piece of floor from a chair's seat.
//
//   1. Every labelled voxel's normal from the TSDF gradient (towards the observed side).
//   2. Dominant normal directions: the densest direction, refined as the mean of the normals
//      within GsmParams::structure_normal_deg of it, removed, and again (at most kMaxDirections).
//   3. Per direction, planes are the peaks of the histogram of the voxels' surface offsets
//      (voxel centre less its TSDF distance along the normal, so the lattice does not quantise
//      them). Each plane's distance band is three robust σ of its own offsets, at least a voxel:
//      it grows with the depth noise σ(z) where the plane was seen from and with the drift of
//      the poses. Parallel planes whose bands touch are one plane: two sheets of one wall seen
//      from drifted poses, a rug on the floor, coplanar pieces of one counter.
//   4. A plane's voxels fall into faces (connected in the plane, across one-cell holes). A face
//      bounds the room when it is bigger than a face of furniture (GsmParams::
//      object_structure_extent_m × structure_min_span_m) and nothing observed lies behind it
//      inside its footprint (at most structure_max_behind_share of its voxel count): nothing is
//      seen behind a floor, a wall or a ceiling, and a cabinet front or a counter top hides what
//      is behind; under a table top there are chairs and floor.
//   5. With an up direction (the cameras' mean image up, when it is consistent), bounding faces
//      are named: floor (the lowest facing up), ceiling (facing down), wall (vertical), support
//      (other faces facing up: counter tops), vertical face (other vertical: cabinet fronts).
//      Which voxels are structure never depends on up: a map whose world z is not up gets the
//      same barrier.
//
// The result is a function of the map's TSDF and main labels (and the up hint for the names
// only), so a map restored from its saved blocks gives the same structure as the live one.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "absl/container/flat_hash_map.h"
#include "core/common/params.h"
#include "core/gsm/label_voxel.h"
#include "core/tsdf/tsdf_layer.h"

namespace objdb::gsm {

using LabelBlocks = absl::flat_hash_map<tsdf::BlockIndex, std::vector<Label>, tsdf::BlockIndexHash>;

// The blocks of `labels` in index order (z, y, x): results must not depend on hash order.
std::vector<const LabelBlocks::value_type*> sortedBlocks(const LabelBlocks& labels);

enum class StructureKind : uint8_t {
  kNone = 0,       // a plane, not room structure (a table top, a seat)
  kFloor,
  kCeiling,
  kWall,
  kSupport,        // bounding, facing up, above the floor: a counter top
  kVerticalFace,   // bounding, vertical, not a wall: a cabinet front, a partition
  kBoundary,       // bounding, but no up direction to name it
};
const char* structureKindName(StructureKind kind);

struct RoomPlane {
  Eigen::Vector3f normal = Eigen::Vector3f::UnitZ();  // unit, towards the observed side
  float offset_m = 0.0f;  // normal · p of its centre, world frame
  float band_m = 0.0f;    // half-width of its distance band
  int sheets = 1;         // parallel sheets joined into it (> 1: a drift-doubled surface)
  size_t voxels = 0;      // surface voxels in its band
  size_t barrier_voxels = 0;  // of them on bounding faces
  float span_m[2] = {0.0f, 0.0f};  // its largest face's in-plane spans, smaller first
  StructureKind kind = StructureKind::kNone;  // of its largest bounding face (kNone: none)
};

struct RoomStructure {
  bool up_found = false;
  Eigen::Vector3f up = Eigen::Vector3f::Zero();  // unit when up_found
  std::vector<RoomPlane> planes;                 // largest first
  // Surface voxels on bounding faces (packGridKey of the map voxel) → index into planes.
  absl::flat_hash_map<uint64_t, int> barrier;
  size_t surface_voxels = 0;  // labelled voxels looked at
  double ms = 0.0;            // time taken

  bool isBarrier(const tsdf::VoxelIndex& v) const;
  size_t structurePlanes() const;  // planes with a bounding face
  // One line: "up found (0.00 0.00 1.00); 5 structure planes of 12 (floor, 3 walls, support);
  // 41 % of the surface".
  std::string summary() const;
};

// At most this many plane directions and planes per map.
constexpr int kMaxDirections = 8;
constexpr int kMaxPlanes = 48;

// Finds the room structure of a map: `labels` are its main labels per block (0 = none); only
// labelled voxels are surface here. `up_hint` (zero: none) is the cameras' mean image up; it
// names the faces and is checked against the dominant normals (a hint more than
// structure_normal_deg away from every direction is not used).
RoomStructure findRoomStructure(const tsdf::TsdfLayer& layer, const LabelBlocks& labels,
                                const GsmParams& params,
                                const Eigen::Vector3f& up_hint = Eigen::Vector3f::Zero());

}  // namespace objdb::gsm
