// The offline front end shared by `objdb gsm` and `objdb ingest`: every N-th frame of a dataset
// is segmented and fused into a Global Segmentation Map; raw segments are handed on as they are
// extracted (idle labels after each frame, every remaining label at the end). Bad frames are
// skipped, reported and counted.
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "core/gsm/gsm.h"
#include "core/io/dataset.h"
#include "core/segmentation/depth_segmenter.h"

namespace objdb::cli {

struct FrameLoopStats {
  size_t used = 0, rejected = 0, merges = 0;
  double segmentation_ms = 0, fusion_ms = 0;  // summed over used frames
};

// Segments extracted after a frame, and the labels the GSM withdrew (gsm::Gsm::takeWithdrawn:
// merged into another label; whoever kept their earlier segments drops them).
using SegmentSink =
    std::function<Status(std::vector<gsm::RawSegment> segments, std::vector<gsm::Label> withdrawn)>;

// Errors: a frame that cannot be loaded, or the sink's error (the loop stops there).
StatusOr<FrameLoopStats> segmentAndFuse(const io::Dataset& dataset,
                                        segmentation::DepthSegmenter* segmenter,
                                        gsm::Gsm* map, size_t every, const std::string& command,
                                        const std::string& progress_label,
                                        const SegmentSink& sink);

}  // namespace objdb::cli
