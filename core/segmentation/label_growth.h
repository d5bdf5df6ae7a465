// Label growth, the last step of DepthSegmenter::segment: boundary pixels join the segment of
// a neighbour on their surface. Internal to the segmenter (its own file for size and speed).
#pragma once

#include "core/common/image.h"
#include "core/common/intrinsics.h"
#include "core/segmentation/depth_segmenter.h"

namespace objdb::segmentation {

// Grows labels into measured pixels with a normal (segments promise unit normals) that have no
// label: `iterations` rings, each pixel taking its nearest labelled 4-neighbour of the previous
// ring within `max_distance` (see DepthSegmenter::segment). The first ring is one vectorised
// pass over the image; every later ring looks only at the unlabelled neighbours of the pixels
// the ring before labelled (a pixel whose neighbours did not change would fail again).
void growLabels(const DepthImage& depth, const Planar3f& normals, const Intrinsics& k,
                int iterations, float max_distance, LabelImage* labels);

}  // namespace objdb::segmentation
