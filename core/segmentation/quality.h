// Segmentation quality against ground-truth instance masks: coverage (IoU of
// each object's best segment, weighted by object size), under-segmentation (segments spanning
// two or more instances) and over-segmentation (segments per object). Also, for composite objects
// that a geometric segmenter cuts into parts on purpose (a chair's seat, back and legs): union
// coverage, the IoU of the union of the segments lying mostly inside each object.
#pragma once

#include <cstdint>
#include <map>
#include <set>

#include "core/common/image.h"
#include "core/segmentation/depth_segmenter.h"

namespace objdb::segmentation {

struct QualityCounts {
  // Sums over frames; ratios are computed by the accessors.
  double weighted_iou = 0.0;       // Σ pixels(object) · best IoU(object)
  double weighted_union_iou = 0.0; // Σ pixels(object) · IoU(object, its majority segments)
  double object_pixels = 0.0;      // Σ pixels(object)
  size_t objects = 0;              // object observations (object × frame)
  size_t segments = 0;
  size_t under_segmented = 0;      // segments with ≥ 2 instances each above the share limit
  size_t object_segments = 0;      // segments whose majority instance is an object

  double coverage() const { return object_pixels > 0 ? weighted_iou / object_pixels : 0.0; }
  double unionCoverage() const {
    return object_pixels > 0 ? weighted_union_iou / object_pixels : 0.0;
  }
  double underSegmentationRate() const {
    return segments ? double(under_segmented) / double(segments) : 0.0;
  }
  double segmentsPerObject() const { return objects ? double(object_segments) / double(objects) : 0.0; }
  void add(const QualityCounts& other);
};

struct QualityOptions {
  std::set<uint16_t> structure_ids;  // floor / walls: scored for under-segmentation only
  double under_share = 0.10;         // an instance counts in a segment above this share
  int min_object_pixels = 50;        // smaller ground-truth objects in a frame are not scored
};

// Scores one frame's labels (0 = none) against its instance mask (0 = none). `best_iou`
// (optional) receives each scored object's best IoU and pixel count.
struct ObjectScore {
  double best_iou = 0.0;
  double union_iou = 0.0;  // the union of the segments whose majority is this object
  size_t pixels = 0;
  int32_t best_label = 0;  // the segment with the best IoU (0 = none overlaps the object)
};
QualityCounts evaluateSegmentation(const LabelImage& labels, const InstanceImage& instances,
                                   const QualityOptions& options,
                                   std::map<uint16_t, ObjectScore>* best_iou = nullptr);

}  // namespace objdb::segmentation
