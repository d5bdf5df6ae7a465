// Object hypotheses above the GSM's convex labels (ours). The segmenter cuts frames
// into convex parts (paper §III-A), so a chair is a seat, a back and legs. Here the labels of a
// map are grouped into objects: two labels connect when their voxels touch (within
// GsmParams::object_gap_m, at least object_min_contact_voxels voxels of the two next to the
// other), unless
//   - either is room structure: most of its voxels lie on a bounding face of the room found in
//     the whole map (room_structure.h: a floor, a wall, a ceiling, a cabinet front, a counter
//     top), or it alone is larger than furniture can be (GsmParams::object_max_extent_m);
//     structure labels stay objects of their own. The voxels of other labels that lie on a
//     bounding face are cut from their objects (ObjectGroups::cut): a chair's label holding a
//     strip of floor keeps the chair only;
//   - both stand on the floor by themselves: with an up direction and a floor, a part whose
//     lowest voxel lies in the floor's band stands (a leg), and carries a part it touches in the
//     top quarter of its height (the seat it ends under); the units so joined stand when one of
//     their parts does. Two standing units that touch elsewhere stay apart (a chair tucked under
//     a table, its seat against the table's leg); a unit that does not stand (a chair's back, a
//     cow's head) joins the one it touches most. Without a floor, every contact connects;
//   - one rests on the other: the other is planar there (the whole label, or its surface within
//     5 voxels of the contact: a table top under one label with its apron is flat where a mug
//     stands), the first lies on its observed side (where the TSDF is positive), and the other's
//     surface continues beyond the contact in all four in-plane directions within
//     object_support_probe_m, or in three when the contact is a small footprint on it (at most
//     half its extent along both axes; the fourth side may lie in the object's shadow), and what
//     rests there, grouped without this cut, spans at most object_support_max_ratio of the
//     support's extent along both its axes: a mug on a table top, a box on a shelf or on a piece
//     of floor, a picture on a door. A back standing along a seat's rear edge, legs under it, or
//     a pedestal carrying a seat as wide as its base do not rest: they stay parts of the chair.
// An object is a connected component of the rest; one larger than furniture can be
// (GsmParams::object_max_extent_m, full span along its principal axes) falls back to its parts,
// each an object of its own (counted: ObjectGroups::giant_fallbacks). Its id is its smallest
// label, so it is stable
// while labels merge (the older label survives) and parts join it. The grouping is a function
// of the map's main labels (the per-voxel label-count history decides them), recomputed from
// them: merges and splits of objects lose nothing, the parts keep their labels.
//
// Across a shadow (GsmParams::object_shadow_gap_m): a seat or a table top hides the top of the
// column it stands on, so the two never touch. A label standing on a structure is probed along
// that structure's normal; a probe that reaches another label through unobserved space (and no
// observed free space), farther than touching and within the gap, connects the two when the
// other's object floats: as grouped so far it touches no structure and rests on no support, so
// something unseen must carry it. A desk on its own legs takes nothing across its shadow.
//
// Structure does not keep everything it is labelled with: its voxels that stand off its plane on
// the observed side (by more than a voxel and more than twice the plane's own spread, up to
// GsmParams::object_annex_height_m), connected to an object's voxels and inside that object's
// footprint on the plane (its extent along both in-plane axes, a voxel more), belong to that
// object. A chair's or a table's base disc is 3 cm high: the segmenter finds no edge between it
// and the floor, so its voxels are voted into the floor's label, but they stand off the floor's
// plane. They join the object as part of the label they touch (breadth first from every
// touching voxel at once, in voxel order), and leave the structure's segment. What no object
// reaches that way falls into connected islands. An object that floats (as finally grouped it
// touches no structure and rests on no support) entirely above the annexed band takes an island
// that lies at least half inside its footprint, as the member label nearest the plane: the
// column of a pedestal chair seen from afar is too thin to carry a label, and its seat floats
// over the base. Of several such objects the one whose footprint holds most of the island takes
// it. An object standing on its legs takes no island: a mat under a table stays floor.
#pragma once

#include <map>
#include <vector>

#include "absl/container/flat_hash_map.h"
#include "absl/container/flat_hash_set.h"
#include "core/common/params.h"
#include "core/gsm/label_voxel.h"
#include "core/gsm/room_structure.h"
#include "core/tsdf/tsdf_layer.h"

namespace objdb::gsm {

// A structure voxel an object takes (see above), as part `part` of the object.
struct AnnexedVoxel {
  tsdf::VoxelIndex voxel;
  Label part = 0;
};

struct ObjectGroups {
  std::map<Label, std::vector<Label>> members;   // object id (its smallest label) → labels, sorted
  absl::flat_hash_map<Label, Label> object_of;   // label → object id
  absl::flat_hash_set<Label> structure;          // labels that are room structure
  // Object id → the structure voxels it takes, in the (deterministic) order they were taken; and
  // each such voxel (packGridKey) → its part.
  std::map<Label, std::vector<AnnexedVoxel>> annexed;
  absl::flat_hash_map<uint64_t, Label> annexed_part;
  size_t contacts = 0;  // label pairs that touch (neither structure)
  size_t supports = 0;  // of them, not connected because one rests on the other
  size_t shadow_joins = 0;  // label pairs connected across a shadow
  size_t islands = 0;       // pieces of structure taken by a floating object above them
  // Objects larger than GsmParams::object_max_extent_m that fell back to their parts, and single
  // labels that large made structure.
  size_t standing_cuts = 0;  // touching units that each stand on the floor, kept apart
  size_t giant_fallbacks = 0;
  size_t giant_labels = 0;
  // Voxels of object labels that lie on a bounding face of the room (packGridKey): cut from
  // their objects (a chair's label holding a strip of floor).
  absl::flat_hash_set<uint64_t> cut;
  RoomStructure room;  // what room_structure.h found in the map

  // The part a map voxel with main label `label` counts as: the annexing object's part for an
  // annexed voxel, else `label` itself. The object is object_of of that.
  Label partAt(const tsdf::VoxelIndex& v, Label label) const;
};

// Groups the labels of `labels` (main label per voxel of each block, 0 = none; `layer` gives the
// TSDF for the observed side of a surface). Every label present is in exactly one object.
// `up_hint`: the cameras' mean image up (zero: unknown), for naming structure only. `room`: the
// room structure found before (null: found now from the map, findRoomStructure).
ObjectGroups groupObjects(const tsdf::TsdfLayer& layer, const LabelBlocks& labels,
                          const GsmParams& params,
                          const Eigen::Vector3f& up_hint = Eigen::Vector3f::Zero(),
                          const RoomStructure* room = nullptr);

}  // namespace objdb::gsm
