// One session's frame pipeline (docs/architecture.md, data flow steps 1-4; paper §III-A, §III-B): a frame
// is validated and decoded, segmented, and fused into the session's Global Segmentation Map;
// idle segments are extracted as database jobs, each carrying a snapshot of the map as it was at
// extraction, so that the database can verify a merge against this live scene (paper §III-C.4,
// model to scene) before the session has ended. Nothing here talks gRPC or SQLite: the service
// wraps it (server/object_database_service.cpp).
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "core/common/intrinsics.h"
#include "core/common/params.h"
#include "core/common/status.h"
#include "core/database/model_store.h"
#include "core/gsm/gsm.h"
#include "core/segmentation/depth_segmenter.h"
#include "objdb/v1/objdb.pb.h"
#include "server/proto_convert.h"

namespace objdb::server {

struct IngestStream;

// A copy of a live map to save, made by the thread that owns the map.
struct MapCopy {
  std::shared_ptr<const tsdf::TsdfLayer> map;
  std::shared_ptr<const gsm::LabelBlocks> labels;
  int64_t frames = 0;
  double copy_ms = 0.0;
};

// A raw segment waiting for the database, with why it was extracted.
struct RawSegmentJob {
  gsm::RawSegment segment;
  v1::SegmentExtracted::Reason reason = v1::SegmentExtracted::IDLE;
  uint64_t last_frame_index = 0;  // client index of the last frame that observed it
  // The session's map (TSDF) when the segment was extracted, blocks shared copy-on-write with
  // the live map: the scene this session's poses are verified against.
  std::shared_ptr<const tsdf::TsdfLayer> scene;
  // Not a segment to insert: the GSM withdrew segment.label (gsm::Gsm::takeWithdrawn), whose
  // earlier segment the database gives back.
  bool withdraw = false;
  // Several servers on one database: `scene` with its main labels, published as the session's
  // saved map before this job (the first of its extraction) is inserted, so that other servers
  // verify poses in this live session against the map this server verifies them against.
  std::shared_ptr<const MapCopy> publish;
};

// One session with a map in memory: from its header until EndSession.
struct LiveSession {
  std::string name;
  Intrinsics intrinsics;
  Params params;
  std::string client_info;
  double started_unix_s = 0.0;
  // Set (the service's flag) when the store is shared by several servers: while it is true,
  // each extraction's map snapshot is published (RawSegmentJob::publish).
  const std::atomic<bool>* publish_scenes = nullptr;

  // Used by one thread at a time: the stream's frame worker, then (after it) the database thread.
  std::optional<segmentation::DepthSegmenter> segmenter;
  std::optional<gsm::Gsm> map;
  std::vector<uint64_t> frame_indices;  // client index of each integrated frame (GSM frame order)
  bool has_frame = false;
  uint64_t last_index = 0;
  double last_timestamp = 0.0;

  // EndSession's segments (the database thread's): extracted once, inserted front first, so a
  // failed flush can be retried without losing any.
  bool flush_extracted = false;
  bool flush_scene_stored = false;  // the final map is stored (before the flush's inserts)
  std::deque<RawSegmentJob> flush_jobs;

  std::mutex mutex;  // guards what follows
  v1::SessionState state = v1::SESSION_STATE_OPEN;
  bool streaming = true;  // its Ingest stream (frame worker) is still running
  double ended_unix_s = 0.0;
  v1::SessionCounters counters;
  std::weak_ptr<IngestStream> stream;
  std::chrono::steady_clock::time_point stream_gone;  // when `streaming` became false
  bool end_queued = false;  // the server queued its own end (idle too long, or stopping)
  // This server no longer holds the session's lease (another may have taken it over): nothing
  // more of it is written.
  bool lease_lost = false;
  // Database jobs to queue when the frame worker is done (EndSession of an interrupted stream).
  std::vector<std::function<void()>> after_stream;
  // The newest map snapshot handed to the database (with the last extracted segments): the
  // scene that models of this session are verified against while it is live.
  std::shared_ptr<const tsdf::TsdfLayer> scene;

  // Saving the map (maybeSaveMap): the frame worker's clock, a save waiting in the queue, and
  // the frame count of the last save written.
  std::chrono::steady_clock::time_point map_saved_at{};
  std::atomic<bool> map_save_pending{false};
  // Save the map at the next chance, whatever the clock (another server came: publish it).
  std::atomic<bool> publish_requested{false};
  std::atomic<int64_t> map_saved_frames{0};
  // The database thread's: the map last written as the saved map, the base of the next write
  // (only the blocks that changed since are written; none: the whole map).
  std::optional<MapCopy> saved_base;
  int64_t idle_save_tried = -1;  // frame count the janitor last queued a save for (mutex)

  v1::SessionCounters snapshot() {
    std::lock_guard lock(mutex);
    return counters;
  }
  bool ended() {
    std::lock_guard lock(mutex);
    return state == v1::SESSION_STATE_ENDED;
  }
  bool leaseLost() {
    std::lock_guard lock(mutex);
    return lease_lost;
  }
  std::shared_ptr<const tsdf::TsdfLayer> currentScene() {
    std::lock_guard lock(mutex);
    return scene;
  }
};

// Checks a session header (name, client info, intrinsics, per-session parameter overrides on
// top of `server_params`): the session it describes, without its pipeline yet. What the database
// must agree to (model settings, a unique name) is the caller's. Errors: INVALID_ARGUMENT naming
// the header field.
StatusOr<std::shared_ptr<LiveSession>> sessionFromHeader(const v1::SessionHeader& header,
                                                         const Params& server_params);
// Builds the session's segmenter and map (its parameters are checked).
Status startPipeline(LiveSession& session, int integration_threads);

// Steps 1-2 of one frame, which read nothing of the session's map: its depth (and colour)
// decoded and segmented. Runs on the session's segmentation thread, one frame ahead of the
// thread that fuses (integrateFrame), so that segmenting frame k+1 overlaps fusing frame k.
// A frame that fails here is rejected by integrateFrame with this error, after the checks that
// come before decoding (order, timestamp, pose), as if it had run in one step.
struct PreparedFrame {
  Status status = absl::OkStatus();  // the first decode or segmentation error
  DepthCounts counts;
  DepthImage depth;
  std::optional<ColorImage> color;
  segmentation::SegmentationResult segments;
};
PreparedFrame prepareFrame(segmentation::DepthSegmenter& segmenter, const Intrinsics& intrinsics,
                           const v1::Frame& frame);

// Step 3: checks order, timestamp and pose, then fuses the prepared frame into the map; fills
// ack->frame. Errors (INVALID_ARGUMENT): the frame is bad and nothing of it was integrated; the
// session carries on.
Status integrateFrame(LiveSession& session, const v1::Frame& frame, const PreparedFrame& prepared,
                      v1::FrameAck* ack);

// Step 4: the segments idle for the GSM's idle time (every live one with `everything`), as jobs
// that share one snapshot of the map, which also becomes session.scene (and, while
// session.publish_scenes says so, the first job's `publish`, with the map's main labels). Runs
// on the thread that owns the map.
std::vector<RawSegmentJob> extractSegments(LiveSession& session, bool everything,
                                           v1::SegmentExtracted::Reason reason);

// `snapshot`: a snapshot of the map's TSDF taken already (null: one is taken).
MapCopy copyMap(const gsm::Gsm& map, std::shared_ptr<const tsdf::TsdfLayer> snapshot = nullptr);

// Whether a stored raw segment is `segment`: the same pose (hence the same grid origin), the same
// voxels (both lists in extractRawSegment's order) and the same TSDF values around them. Then
// re-inserting it would change nothing; a label observed again after its extraction has new TSDF
// values even where its voxels stayed.
bool sameSegment(const database::RawSegmentRecord& stored, const gsm::RawSegment& segment);

}  // namespace objdb::server
