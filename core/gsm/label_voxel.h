// The label history of one voxel (paper §III-B): instead of one label and a confidence
// (Tateno et al.), every label fused into the voxel keeps its vote count, and the main label is
// the most voted. Bounded at kLabelSlots entries, 16 bytes per voxel:
//  - counts are 8-bit; when one would pass 255 every count of the voxel is halved first
//    (ratios, hence the main label, are kept);
//  - a new label arriving at a full voxel takes the slot of the least-voted label and inherits
//    its count + 1 (the space-saving rule: a label voted more than 1/kLabelSlots of the time is
//    never lost, and counts stay an upper bound of its true votes).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>

namespace objdb::gsm {

using Label = uint32_t;  // global label id; 0 = none
inline constexpr int kLabelSlots = 3;

struct LabelVoxel {
  std::array<Label, kLabelSlots> labels{};    // 0 = empty slot
  std::array<uint8_t, kLabelSlots> counts{};
  uint8_t reserved = 0;

  // Adds one vote for `label` (≠ 0) following the rules above.
  void vote(Label label);
  // The ablation of the paper's comparison (Tateno et al.): one label and a confidence in slot 0.
  // The same label raises the confidence; another lowers it and takes over when it reaches 0.
  void voteSingle(Label label);
  // The most voted label (first slot on ties); 0 when empty.
  Label mainLabel() const;
  uint32_t countOf(Label label) const;
  bool empty() const { return labels[0] == 0 && labels[1] == 0 && labels[2] == 0; }
};
static_assert(sizeof(LabelVoxel) == 16, "label voxels are 16 bytes");

}  // namespace objdb::gsm
