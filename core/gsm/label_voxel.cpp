#include "core/gsm/label_voxel.h"

namespace objdb::gsm {

void LabelVoxel::vote(Label label) {
  int slot = -1, empty_slot = -1, weakest = 0;
  for (int i = 0; i < kLabelSlots; ++i) {
    if (labels[size_t(i)] == label) slot = i;
    if (labels[size_t(i)] == 0 && empty_slot < 0) empty_slot = i;
    if (counts[size_t(i)] < counts[size_t(weakest)]) weakest = i;
  }
  if (slot < 0 && empty_slot >= 0) {
    slot = empty_slot;
    labels[size_t(slot)] = label;
    counts[size_t(slot)] = 0;
  } else if (slot < 0) {
    slot = weakest;  // space-saving replacement: inherit the evicted count
    labels[size_t(slot)] = label;
  }
  if (counts[size_t(slot)] == 255) {
    for (auto& c : counts) c = uint8_t(c / 2);
  }
  ++counts[size_t(slot)];
}

void LabelVoxel::voteSingle(Label label) {
  if (labels[0] == label || labels[0] == 0) {
    labels[0] = label;
    if (counts[0] < 255) ++counts[0];
  } else if (--counts[0] == 0) {
    labels[0] = label;
    counts[0] = 1;
  }
}

Label LabelVoxel::mainLabel() const {
  int best = -1;
  for (int i = 0; i < kLabelSlots; ++i) {
    if (labels[size_t(i)] == 0) continue;
    if (best < 0 || counts[size_t(i)] > counts[size_t(best)]) best = i;
  }
  return best < 0 ? 0 : labels[size_t(best)];
}

uint32_t LabelVoxel::countOf(Label label) const {
  for (int i = 0; i < kLabelSlots; ++i) {
    if (labels[size_t(i)] == label) return counts[size_t(i)];
  }
  return 0;
}

}  // namespace objdb::gsm
