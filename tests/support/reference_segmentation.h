// Slow, obvious reference for the last two steps of the depth segmentation (paper §III-A):
// connected components of the non-boundary pixels, the minimum-size filter and label growth into
// boundary pixels. Differential tests compare DepthSegmenter's labels with it.
#pragma once

#include <cstddef>
#include <cstdint>

#include "core/common/image.h"
#include "core/common/intrinsics.h"

namespace objdb::testing {

struct ReferenceLabels {
  Image<int32_t> labels;  // 0 = none; 1.. in raster order of each region's first pixel
  int32_t segments = 0;
  size_t dropped_small = 0;
  // Pixels that had two differently labelled neighbours at exactly the same 3D distance when they
  // were grown: either label is right.
  Image<uint8_t> tie;
};

// `boundaries`: 1 = boundary or invalid. Regions are 4-connected; a region with fewer than
// `min_segment_px` pixels is dropped. Then, `growth_iterations` times, every unlabelled pixel with
// valid `depth` and a normal (`has_normal` = 1) takes the label of its 4-neighbour whose back-projected point is closest, if
// within `max_growth_distance_m` (all pixels of one pass decided from the previous pass).
ReferenceLabels referenceLabels(const Image<uint8_t>& boundaries, const DepthImage& depth,
                                const Image<uint8_t>& has_normal, const Intrinsics& intrinsics, int min_segment_px,
                                int growth_iterations, float max_growth_distance_m);

}  // namespace objdb::testing
