#include "client/frame_loop.h"

#include <cstdio>

#include "client/progress.h"

namespace objdb::cli {

StatusOr<FrameLoopStats> segmentAndFuse(const io::Dataset& ds,
                                        segmentation::DepthSegmenter* segmenter,
                                        gsm::Gsm* map, size_t every, const std::string& command,
                                        const std::string& progress_label,
                                        const SegmentSink& sink) {
  FrameLoopStats stats;
  ProgressBar bar(progress_label, (ds.size() + every - 1) / every);
  for (size_t i = 0; i < ds.size(); i += every) {
    OBJDB_ASSIGN_OR_RETURN(const Frame frame, ds.loadFrame(i));
    const ColorImage* color = frame.color ? &*frame.color : nullptr;
    auto seg = segmenter->segment(frame.depth, color);
    auto fused = seg.ok() ? map->integrate(frame.depth, seg->labels, frame.T_world_camera, color)
                          : StatusOr<gsm::GsmFrameResult>(seg.status());
    if (!fused.ok()) {
      std::fprintf(stderr, "\nobjdb %s: frame %zu skipped: %s\n", command.c_str(), i,
                   std::string(fused.status().message()).c_str());
      ++stats.rejected;
    } else {
      ++stats.used;
      stats.segmentation_ms += seg->timings.total_ms;
      stats.fusion_ms += fused->tsdf.milliseconds;
      stats.merges += fused->merges;
      std::vector<gsm::RawSegment> segments = map->extractIdle();
      OBJDB_RETURN_IF_ERROR(sink(std::move(segments), map->takeWithdrawn()));
    }
    bar.update(stats.used + stats.rejected);
  }
  bar.finish();
  std::vector<gsm::RawSegment> segments = map->extractIdle(true);
  OBJDB_RETURN_IF_ERROR(sink(std::move(segments), map->takeWithdrawn()));
  return stats;
}

}  // namespace objdb::cli
