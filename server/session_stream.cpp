// ObjectDatabaseService's Ingest pipeline (object_database_service.h): a stream's two stages —
// the segmentation thread one frame ahead of the frame worker, which fuses, acks, extracts idle
// segments for the database queue and saves the map now and then — and the end of a stream.
#include "server/object_database_service.h"

#include <atomic>
#include <condition_variable>
#include <deque>
#include <future>
#include <mutex>
#include <thread>
#include <utility>

#include "absl/strings/str_format.h"
#include "core/common/logging.h"
#include "core/database/object_database.h"
#include "server/ingest_stream.h"
#include "server/job_queue.h"
#include "server/proto_convert.h"
#include "server/service_util.h"
#include "server/session/live_session.h"
#include "server/status_convert.h"

namespace objdb::server {

void ObjectDatabaseService::runStream(std::shared_ptr<IngestStream> stream) {
  v1::SessionHeader header;
  {
    std::lock_guard lock(stream->mutex);
    if (stream->cancelled) {  // gone before its session existed: nothing to open
      stream->finish(grpc::Status(grpc::StatusCode::CANCELLED, "cancelled"));
      return;
    }
    header = stream->header;
  }
  v1::IngestResponse first;
  auto opened = openSession(header, stream, first.mutable_opened());
  if (!opened.ok()) {
    std::lock_guard lock(stream->mutex);
    stream->cancelled = true;
    stream->finish(toGrpcStatus(opened.status()));
    return;
  }
  {
    std::lock_guard lock(stream->mutex);
    stream->session = *opened;
  }
  stream->send(std::move(first));
  LiveSession& session = **opened;
  // Two stages, one frame apart: the segmentation thread decodes and segments frame k+1 while
  // this thread fuses frame k (and extracts, and hands segments to the database's thread).
  // Frames stay in order: one producer, one consumer, a queue of kSegmentedAhead.
  constexpr size_t kSegmentedAhead = 1;
  struct Segmented {
    v1::Frame frame;
    PreparedFrame prepared;
  };
  std::mutex ahead_mutex;
  std::condition_variable ahead_changed;
  std::deque<Segmented> ahead;
  bool segmenter_done = false, input_complete = false;
  std::atomic<bool> stop_segmenting{false};
  std::thread segmenter([&] {
    bool complete = false;
    while (true) {
      v1::Frame frame;
      {
        std::unique_lock lock(stream->mutex);
        stream->changed.wait(lock, [&] {
          return stream->cancelled || stop_segmenting || !stream->inbox.empty() ||
                 stream->input_ended;
        });
        if (stream->cancelled || stop_segmenting) break;
        if (stream->inbox.empty()) {
          complete = true;
          break;
        }
        frame = std::move(stream->inbox.front());
        stream->inbox.pop_front();
        stream->resumeReading();
      }
      Segmented item{std::move(frame), {}};
      item.prepared = prepareFrame(*session.segmenter, session.intrinsics, item.frame);
      std::unique_lock lock(ahead_mutex);
      ahead_changed.wait(lock, [&] { return stop_segmenting || ahead.size() < kSegmentedAhead; });
      if (stop_segmenting) break;
      ahead.push_back(std::move(item));
      ahead_changed.notify_all();
    }
    std::lock_guard lock(ahead_mutex);
    segmenter_done = true;
    input_complete = complete;
    ahead_changed.notify_all();
  });
  bool ended_cleanly = false;
  while (true) {
    // Backpressure from a client that does not read: no more frames until it does.
    if (!stream->waitForReader(options_.max_pending_events, options_.slow_reader_timeout,
                               session.name)) {
      break;
    }
    Segmented item;
    {
      std::unique_lock lock(ahead_mutex);
      ahead_changed.wait(lock, [&] { return !ahead.empty() || segmenter_done; });
      if (ahead.empty()) {
        ended_cleanly = input_complete;
        break;
      }
      item = std::move(ahead.front());
      ahead.pop_front();
      ahead_changed.notify_all();
    }
    {
      std::lock_guard lock(stream->mutex);
      if (stream->cancelled) break;
    }
    processFrame(stream, item.frame, item.prepared);
  }
  // The segmentation thread stops too (it may wait for frames, or for room ahead).
  stop_segmenting = true;
  {
    std::lock_guard lock(ahead_mutex);
    ahead_changed.notify_all();
  }
  {
    std::lock_guard lock(stream->mutex);
    stream->changed.notify_all();
  }
  segmenter.join();
  if (ended_cleanly) {
    // Every segment extracted so far through the database, then the summary.
    std::promise<void> done;
    database_queue_->push([&done] { done.set_value(); });
    done.get_future().wait();
    endStreaming(*opened, false);
    auto summary = summaryOf(session);
    if (summary.ok()) {
      v1::IngestResponse response;
      *response.mutable_summary() = *std::move(summary);
      stream->send(std::move(response));
      stream->finish(grpc::Status::OK);
    } else {
      stream->finish(toGrpcStatus(summary.status()));
    }
    logger("server")->info("session {}: stream closed by the client; open until EndSession",
                           session.name);
    return;
  }
  jobs_cancelled_.fetch_add(1);
  endStreaming(*opened, true);
  forgetEmptySession(*opened);  // when no frame came
  if (session.leaseLost()) {
    stream->finish(toGrpcStatus(lostLease(session.name)));
    return;
  }
  stream->finish(grpc::Status(grpc::StatusCode::CANCELLED, "the Ingest stream was interrupted"));
  logger("server")->warn("session {}: stream interrupted; EndSession can still flush its map",
                         session.name);
}

void ObjectDatabaseService::endStreaming(const std::shared_ptr<LiveSession>& session,
                                         bool interrupted) {
  if (interrupted) {
    // Stored on the database thread, so that it lands before any EndSession flush queued later.
    database_queue_->push([this, session] {
      if (session->ended() || session->leaseLost()) return;
      const v1::SessionCounters counters = session->snapshot();
      (void)store_->finishSession(session->name, storage::SessionState::kInterrupted,
                                  int64_t(counters.frames_integrated()));
      (void)store_->storeSessionCounters(session->name, countersJson(counters));
    });
  }
  std::vector<std::function<void()>> pending;
  {
    std::lock_guard lock(session->mutex);
    session->streaming = false;
    session->stream_gone = std::chrono::steady_clock::now();
    if (interrupted) {
      session->state = v1::SESSION_STATE_INTERRUPTED;
      session->ended_unix_s = nowUnixSeconds();
    }
    pending.swap(session->after_stream);
  }
  for (auto& job : pending) database_queue_->push(std::move(job));
}

void ObjectDatabaseService::processFrame(const std::shared_ptr<IngestStream>& stream_ptr,
                                         const v1::Frame& frame, const PreparedFrame& prepared) {
  IngestStream& stream = *stream_ptr;
  LiveSession& session = *stream.session;
  v1::IngestResponse response;
  v1::FrameAck& ack = *response.mutable_ack();
  ack.set_index(frame.index());
  {
    std::lock_guard lock(session.mutex);
    session.counters.set_frames_received(session.counters.frames_received() + 1);
  }
  auto reject = [&](const Status& status) {
    ack.set_accepted(false);
    ack.set_code(int32_t(status.code()));
    ack.set_reason(std::string(status.message()));
    std::lock_guard lock(session.mutex);
    session.counters.set_frames_rejected(session.counters.frames_rejected() + 1);
    *ack.mutable_session() = session.counters;
  };
  auto run = [&]() -> Status {
    OBJDB_RETURN_IF_ERROR(integrateFrame(session, frame, prepared, &ack));
    std::lock_guard lock(session.mutex);
    session.counters.set_frames_integrated(session.counters.frames_integrated() + 1);
    *ack.mutable_session() = session.counters;
    return absl::OkStatus();
  };
  if (Status processed = run(); !processed.ok()) reject(processed);
  const bool accepted = ack.accepted();
  stream.send(std::move(response));  // moves the ack away
  if (!accepted) return;
  // Overload policy: the frame path never waits for the database. While segment_queue jobs
  // wait for it, idle segments are not extracted after this frame: they stay in the map (still
  // fused, still voted on) and are extracted after a later frame once the database has caught
  // up, or at the session's flush. Nothing is lost; segments reach the database later.
  if (database_queue_->pending() < options_.segment_queue) {
    std::vector<RawSegmentJob> jobs = extractSegments(session, false, v1::SegmentExtracted::IDLE);
    if (!jobs.empty()) queueInserts(stream_ptr->session, stream_ptr, std::move(jobs));
  } else {
    extractions_deferred_.fetch_add(1);
  }
  maybeSaveMap(stream_ptr->session);
}

void ObjectDatabaseService::maybeSaveMap(const std::shared_ptr<LiveSession>& session) {
  // Other servers came (updatePublication): the map now, whatever the clock says.
  const bool requested = session->publish_requested.load();
  if (options_.save_map_every.count() <= 0 && !requested) return;
  const auto now = std::chrono::steady_clock::now();
  if (session->map_saved_at == std::chrono::steady_clock::time_point{} && !requested) {
    session->map_saved_at = now;  // the first frame starts the clock
    return;
  }
  if (session->map_save_pending) return;  // one save at a time (a request waits a frame)
  if (!requested && now - session->map_saved_at < options_.save_map_every) return;
  session->publish_requested = false;
  session->map_saved_at = now;
  session->map_save_pending = true;
  // Behind the inserts queued before it; never waiting (one save at a time is pending).
  database_queue_->push([this, session, copy = copyMap(*session->map)] {
    storeSavedMap(*session, copy);
    session->map_save_pending = false;
  });
}

void ObjectDatabaseService::saveIdleMap(const std::shared_ptr<LiveSession>& session) {
  // The stream is gone: the map is the database thread's now (flush frees it once ended).
  if (session->map) storeSavedMap(*session, copyMap(*session->map));
  session->map_save_pending = false;
}

void ObjectDatabaseService::storeSavedMap(LiveSession& session, const MapCopy& copy) {
  if (session.ended()) return;
  const auto start = std::chrono::steady_clock::now();
  const Status saved = writeSavedMapOf(*store_, session.name, copy, &session.saved_base);
  const double ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  if (!saved.ok()) {
    logger("server")->warn("session {}: saving its map failed (a crash would lose more, and other "
                           "servers verify against an older one): {}",
                           session.name, std::string(saved.message()));
    return;
  }
  session.map_saved_frames = copy.frames;
  // What a crash would leave of the counters (a restart ends the session from this map).
  (void)store_->storeSessionCounters(session.name, countersJson(session.snapshot()));
  if (publish_maps_) published_scenes_.recordPublished(ms);
  logger("server")->debug(
      "session {}: map saved after {} frames ({} blocks; copied in {:.0f} ms, written in {:.0f} "
      "ms)",
      session.name, copy.frames, copy.map->numBlocks(), copy.copy_ms, ms);
}

void ObjectDatabaseService::queueInserts(const std::shared_ptr<LiveSession>& session,
                                         const std::shared_ptr<IngestStream>& stream,
                                         std::vector<RawSegmentJob> jobs) {
  for (auto& job : jobs) {
    auto shared = std::make_shared<RawSegmentJob>(std::move(job));
    auto work = [this, session, stream, shared] { (void)insert(*session, stream.get(), *shared); };
    database_queue_->push(std::move(work));
  }
}

}  // namespace objdb::server
