#include "core/segmentation/quality.h"

#include <algorithm>
#include <map>
#include <unordered_map>

namespace objdb::segmentation {

void QualityCounts::add(const QualityCounts& o) {
  weighted_iou += o.weighted_iou;
  weighted_union_iou += o.weighted_union_iou;
  object_pixels += o.object_pixels;
  objects += o.objects;
  segments += o.segments;
  under_segmented += o.under_segmented;
  object_segments += o.object_segments;
}

QualityCounts evaluateSegmentation(const LabelImage& labels, const InstanceImage& instances,
                                   const QualityOptions& options,
                                   std::map<uint16_t, ObjectScore>* scores) {
  QualityCounts q;
  // Overlap table (segment, instance) → pixels, plus per-segment and per-instance totals.
  std::map<std::pair<int32_t, uint16_t>, size_t> overlap;
  std::unordered_map<int32_t, size_t> segment_size;
  std::unordered_map<uint16_t, size_t> instance_size;
  for (size_t i = 0; i < labels.data.size(); ++i) {
    const int32_t l = labels.data[i];
    const uint16_t g = instances.data[i];
    if (g != 0) ++instance_size[g];
    if (l == 0) continue;
    ++segment_size[l];
    if (g != 0) ++overlap[{l, g}];
  }
  // Per segment: instances inside it. Per instance: the union of its majority segments
  // (pixels of the union, of them on the instance).
  std::unordered_map<int32_t, std::vector<std::pair<uint16_t, size_t>>> per_segment;
  std::unordered_map<uint16_t, std::pair<size_t, size_t>> majority_union;
  for (const auto& [key, n] : overlap) per_segment[key.first].push_back({key.second, n});
  for (const auto& [label, size] : segment_size) {
    ++q.segments;
    const auto it = per_segment.find(label);
    if (it == per_segment.end()) continue;
    int above = 0;
    uint16_t majority = 0;
    size_t majority_n = 0;
    for (const auto& [g, n] : it->second) {
      if (double(n) > options.under_share * double(size)) ++above;
      if (n > majority_n) {
        majority_n = n;
        majority = g;
      }
    }
    if (above >= 2) ++q.under_segmented;
    if (2 * majority_n > size) {  // mostly inside `majority`
      majority_union[majority].first += size;
      majority_union[majority].second += majority_n;
    }
    if (!options.structure_ids.count(majority) && instance_size[majority] >= size_t(options.min_object_pixels)) {
      ++q.object_segments;
    }
  }
  // Per object: best IoU.
  std::unordered_map<uint16_t, double> best_iou;
  std::unordered_map<uint16_t, int32_t> best_label;
  for (const auto& [key, n] : overlap) {
    const auto [label, g] = key;
    const double iou = double(n) / double(segment_size[label] + instance_size[g] - n);
    if (iou > best_iou[g]) {
      best_iou[g] = iou;
      best_label[g] = label;
    }
  }
  for (const auto& [g, size] : instance_size) {
    if (options.structure_ids.count(g) || size < size_t(options.min_object_pixels)) continue;
    ++q.objects;
    q.object_pixels += double(size);
    q.weighted_iou += double(size) * best_iou[g];
    const auto& [union_size, union_on] = majority_union[g];
    const double union_iou =
        union_size ? double(union_on) / double(union_size + size - union_on) : 0.0;
    q.weighted_union_iou += double(size) * union_iou;
    if (scores) (*scores)[g] = ObjectScore{best_iou[g], union_iou, size, best_label[g]};
  }
  return q;
}

}  // namespace objdb::segmentation
