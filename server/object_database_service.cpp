#include "server/object_database_service.h"

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <deque>
#include <future>
#include <mutex>
#include <random>
#include <set>
#include <thread>
#include <utility>

#include "absl/strings/str_format.h"
#include "core/common/logging.h"
#include "core/common/params_io.h"
#include "core/database/object_database.h"
#include "server/ingest_stream.h"
#include "server/job_queue.h"
#include "server/proto_convert.h"
#include "server/service_util.h"
#include "server/session/live_session.h"
#include "server/status_convert.h"
#include "storage/model_settings.h"

namespace objdb::server {
namespace {

// How long after its stream went a session still open gets its last frames saved.
constexpr std::chrono::milliseconds kIdleSaveDelay{5000};

// A lease holder's name unique among the servers on one database: host, process, and a random
// part (a restarted process may get the same pid).
std::string defaultServerId() {
  char host[256] = {};
  if (gethostname(host, sizeof(host) - 1) != 0) std::snprintf(host, sizeof(host), "host");
  std::random_device random;
  return absl::StrFormat("%s:%d:%08x", host, int(getpid()), uint32_t(random()));
}

}  // namespace

StatusOr<std::unique_ptr<ObjectDatabaseService>> ObjectDatabaseService::create(
    const ServiceOptions& options, storage::Store* store) {
  OBJDB_RETURN_IF_ERROR(options.params.validate());
  OBJDB_ASSIGN_OR_RETURN(std::unique_ptr<database::ObjectDatabase> db,
                         database::ObjectDatabase::create(options.params, store));
  // Sessions a stopped server did not end (read only: startRecovery writes).
  OBJDB_ASSIGN_OR_RETURN(const std::vector<storage::SessionInfo> sessions, store->sessions());
  std::vector<storage::SessionInfo> unended;
  for (const auto& s : sessions) {
    if (s.state != storage::SessionState::kEnded) unended.push_back(s);
  }
  std::unique_ptr<ObjectDatabaseService> service(
      new ObjectDatabaseService(options, store, std::move(db)));
  service->unended_ = std::move(unended);
  {
    std::lock_guard lock(service->mutex_);
    for (const auto& s : service->unended_) service->recovering_.insert(s.name);
  }
  return service;
}

ObjectDatabaseService::ObjectDatabaseService(const ServiceOptions& options,
                                             storage::Store* store,
                                             std::unique_ptr<database::ObjectDatabase> db)
    : options_(options),
      store_(store),
      db_(std::move(db)),
      queries_(std::make_unique<QueryPool>("queries", options_.query_threads,
                                           options_.query_queue)),
      scenes_(std::make_unique<QueryPool>("scene meshes", options_.scene_threads,
                                          options_.scene_queue)),
      database_queue_(std::make_unique<JobQueue>()) {
  server_id_ = options_.server_id.empty() ? defaultServerId() : options_.server_id;
  if (store_->sharedByServers()) {
    // Until the lease keeper knows better, publish when others are at work (or unknown).
    const auto others = store_->othersHoldLeases(server_id_);
    publish_maps_ = !others.ok() || *others;
  }
  if (options_.auto_end_after.count() > 0) janitor_ = std::thread([this] { endIdleSessions(); });
  keeper_ = std::thread([this] { keepLeases(); });
}

void ObjectDatabaseService::endIdleSessions() {
  const auto period = std::min<std::chrono::milliseconds>(
      std::chrono::milliseconds(1000), std::max<std::chrono::milliseconds>(
                                           std::chrono::milliseconds(10), options_.auto_end_after / 4));
  std::unique_lock lock(mutex_);
  while (!stopped_) {
    janitor_wake_.wait_for(lock, period);
    if (stopped_) break;
    const auto now = std::chrono::steady_clock::now();
    for (auto& [name, session] : sessions_) {
      std::lock_guard session_lock(session->mutex);
      // A session whose stream is gone keeps its map in memory until it ends: what came after
      // its last save is saved too, a few seconds after the stream went; and at once when other
      // servers came (updatePublication).
      if (!session->streaming && !session->end_queued &&
          session->state != v1::SESSION_STATE_ENDED && !session->map_save_pending) {
        const int64_t frames = int64_t(session->counters.frames_integrated());
        const bool due = options_.save_map_every.count() > 0 &&
                         session->map_saved_frames < frames && session->idle_save_tried < frames &&
                         now - session->stream_gone >= std::min<std::chrono::milliseconds>(
                                                           options_.save_map_every, kIdleSaveDelay);
        if (session->publish_requested.exchange(false) || due) {
          session->map_save_pending = true;
          session->idle_save_tried = frames;  // once
          database_queue_->push([this, session = session] { saveIdleMap(session); });
        }
      }
      if (session->streaming || session->end_queued ||
          session->state == v1::SESSION_STATE_ENDED ||
          now - session->stream_gone < options_.auto_end_after) {
        continue;
      }
      session->end_queued = true;
      logger("server")->info("session {}: no EndSession for {} s after its stream closed; "
                             "ending it",
                             name, options_.auto_end_after.count() / 1000.0);
      database_queue_->push([this, session = session] { (void)endByServer(*session); });
    }
  }
}

Status ObjectDatabaseService::endByServer(LiveSession& session) {
  if (session.ended()) return absl::OkStatus();
  const Status ended = flush(session);
  if (!ended.ok()) {
    logger("server")->error("session {} could not be ended: {}", session.name,
                            std::string(ended.message()));
  }
  return ended;
}

ObjectDatabaseService::~ObjectDatabaseService() { stop(); }

void ObjectDatabaseService::stop() {
  std::list<Worker> workers;
  {
    std::lock_guard lock(mutex_);
    if (stopped_) return;
    stopped_ = true;
    workers.swap(workers_);
  }
  janitor_wake_.notify_all();
  keeper_wake_.notify_all();
  if (janitor_.joinable()) janitor_.join();
  for (auto& w : workers) w.thread.join();
  // The queries waiting are answered (gRPC's drain waits for them), then the pools stop.
  queries_->stop();
  scenes_->stop();
  // No stream runs any more: every session not ended is ended here, its map stored, so that a
  // stop loses nothing (after what is queued already).
  std::vector<std::shared_ptr<LiveSession>> unended;
  {
    std::lock_guard lock(mutex_);
    for (auto& [name, session] : sessions_) {
      std::lock_guard session_lock(session->mutex);
      if (session->state != v1::SESSION_STATE_ENDED) unended.push_back(session);
    }
  }
  for (const auto& session : unended) {
    logger("server")->info("session {} did not end before the server stopped: ending it",
                           session->name);
    database_queue_->push([this, session] {
      if (session->leaseLost() || endByServer(*session).ok()) return;
      (void)store_->finishSession(session->name, storage::SessionState::kInterrupted,
                                  int64_t(session->snapshot().frames_integrated()));
    });
  }
  // The keeper renews the leases until every session is ended or marked interrupted; then they
  // go, and nothing is left for another server to take over.
  database_queue_->push([this] {
    std::unique_lock lock(mutex_);
    keeper_stop_ = true;
    keeper_wake_.notify_all();
  });
  database_queue_.reset();  // runs what is queued, then stops
  if (keeper_.joinable()) keeper_.join();
  std::set<std::string> leased;
  {
    std::lock_guard lock(mutex_);
    leased = leased_;
  }
  for (const auto& name : leased) releaseLease(name);
}

grpc::ServerUnaryReactor* ObjectDatabaseService::answerOffThread(
    grpc::CallbackServerContext* context, std::function<Status()> work) {
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  if (draining_.load()) {
    reactor->Finish(toGrpcStatus(shuttingDown()));
    return reactor;
  }
  const Status queued = queries_->submit([this, reactor, context, work = std::move(work)] {
    if (draining_.load()) {
      reactor->Finish(toGrpcStatus(shuttingDown()));
      return;
    }
    if (context->IsCancelled()) {  // the client went away (or its deadline passed) meanwhile
      reactor->Finish(grpc::Status(grpc::StatusCode::CANCELLED, "the call ended before it ran"));
      return;
    }
    reactor->Finish(toGrpcStatus(work()));
  });
  if (!queued.ok()) {
    queries_refused_.fetch_add(1);
    reactor->Finish(toGrpcStatus(queued));
  }
  return reactor;
}

grpc::ServerUnaryReactor* ObjectDatabaseService::answerAuthorized(
    grpc::CallbackServerContext* context, std::function<Status()> work) {
  if (const Status allowed = authorize(context, options_.token); !allowed.ok()) {
    return finishUnary(context, allowed);
  }
  return answerOffThread(context, std::move(work));
}

void ObjectDatabaseService::startWorker(std::function<void()> work) {
  std::unique_lock lock(mutex_);
  if (stopped_) {  // no call can arrive after stop(); should one, it still gets its answer
    lock.unlock();
    work();
    return;
  }
  // Join the workers that are done.
  for (auto it = workers_.begin(); it != workers_.end();) {
    if (it->finished->load()) {
      it->thread.join();
      it = workers_.erase(it);
    } else {
      ++it;
    }
  }
  auto finished = std::make_shared<std::atomic<bool>>(false);
  workers_.push_back({std::thread([work = std::move(work), finished] {
                        work();
                        finished->store(true);
                      }),
                      finished});
}

std::shared_ptr<LiveSession> ObjectDatabaseService::liveSession(const std::string& name) {
  std::lock_guard lock(mutex_);
  const auto it = sessions_.find(name);
  return it == sessions_.end() ? nullptr : it->second;
}

Status ObjectDatabaseService::checkSessionLimit() {
  size_t open = 0;
  for (const auto& [name, live] : sessions_) {
    std::lock_guard live_lock(live->mutex);
    open += live->state != v1::SESSION_STATE_ENDED ? 1 : 0;
  }
  open += opening_;  // headers between their check and their publication
  if (open < options_.max_open_sessions) return absl::OkStatus();
  return absl::ResourceExhaustedError(absl::StrFormat(
      "too many sessions with a map in memory (%d): end some with EndSession, or start the "
      "server with a larger --max-sessions",
      open));
}

namespace {
// A database write of a session failed: logged, and its stream (if open) ends with the error.
Status failInsert(IngestStream* stream, const Status& failed) {
  logger("server")->error("{}", std::string(failed.message()));
  if (stream != nullptr) {
    std::lock_guard lock(stream->mutex);
    stream->cancelled = true;
    stream->changed.notify_all();
    stream->finish(toGrpcStatus(failed));
  }
  return failed;
}
}  // namespace

Status ObjectDatabaseService::insert(LiveSession& session, IngestStream* stream,
                                     RawSegmentJob& job) {
  const gsm::RawSegment& segment = job.segment;
  if (session.leaseLost()) return lostLease(session.name);
  if (job.withdraw) return withdraw(session, stream, segment.label);
  // Before the segments extracted with it go in (server/session/published_scenes.h).
  if (job.publish != nullptr && !session.flush_scene_stored) storeSavedMap(session, *job.publish);
  // Model-to-scene verification on the live path: this session's poses against the map as it
  // was when the segment was extracted, another live session's against its newest snapshot
  // (published by its server when that is another), ended sessions' against their stored scenes
  // (the database asks the store for those).
  const bool shared = store_->sharedByServers();
  const database::LiveScenes live =
      [this, &session, shared, own = job.scene](
          const std::string& name) -> std::shared_ptr<const tsdf::TsdfLayer> {
    if (name == session.name) return own != nullptr ? own : session.currentScene();
    if (std::shared_ptr<LiveSession> other = liveSession(name)) return other->currentScene();
    return shared ? published_scenes_.scene(name) : nullptr;
  };
  auto report = db_->insertSegment(session.name, segment, live);
  if (!report.ok()) {
    const Status failed = annotate(
        report.status(), absl::StrFormat("inserting segment %d of session %s into the database",
                                         segment.label, session.name));
    insert_errors_.fetch_add(1);
    logger("server")->warn("{}", failed.ToString());
    return failInsert(stream, failed);
  }
  if (report->removed_model != 0) {
    std::lock_guard lock(session.mutex);
    session.counters.set_objects_removed(session.counters.objects_removed() + 1);
  }
  if (report->unusable) {
    // Stored as a raw segment (it replaced any earlier version of itself), held by no model.
    segments_unusable_.fetch_add(1);
    logger("server")->debug("session {}: segment {} stored without a model: {}", session.name,
                            segment.label, report->unusable_reason);
    if (stream != nullptr && report->removed_model != 0) {
      sendObjectEvents(stream, objectEvents(*report, segmentIdOf(session.name, segment.label)));
    }
    return absl::OkStatus();
  }
  candidates_skipped_.fetch_add(report->unreadable_candidates);
  for (const auto& r : report->results) {
    scene_checks_.fetch_add(r.scene_checks);
    poses_without_scene_.fetch_add(r.scenes_missing);
    if (r.stage == "scene") candidates_rejected_by_scene_.fetch_add(1);
    if (r.accepted && r.same_place && report->merged && r.model_id == report->model_id) {
      merges_same_place_.fetch_add(1);
    }
  }
  {
    std::lock_guard lock(timings_mutex_);
    insert_timings_ += report->timings;
    ++inserts_;
  }
  const uint64_t segment_id = segmentIdOf(session.name, segment.label);
  {
    std::lock_guard lock(session.mutex);
    v1::SessionCounters& c = session.counters;
    c.set_segments_extracted(c.segments_extracted() + 1);
    // As the events say: a segment merged, or a model created for it.
    if (report->merged) {
      c.set_objects_merged(c.objects_merged() + 1);
      c.set_objects_joined(c.objects_joined() + report->absorbed().size());
    } else {
      c.set_objects_created(c.objects_created() + 1);
    }
  }
  if (stream == nullptr) return absl::OkStatus();
  v1::IngestResponse extracted;
  v1::SegmentExtracted& e = *extracted.mutable_segment();
  e.set_segment_id(segment_id);
  e.set_gsm_label(segment.label);
  e.set_reason(job.reason);
  e.set_last_frame_index(job.last_frame_index);
  e.set_num_voxels(uint32_t(segment.label_voxels.size()));
  for (const gsm::Label part : segment.parts) e.add_parts(part);
  *e.mutable_t_world_segment() = toProto(segment.T_world_segment);
  if (!segment.label_voxels.empty()) {
    Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::max());
    Eigen::Vector3d hi = -lo;
    for (const auto& v : segment.label_voxels) {
      const Eigen::Vector3d p =
          segment.T_world_segment * segment.grid.voxelCenter(v).cast<double>();
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
    }
    const Eigen::Vector3d half = Eigen::Vector3d::Constant(0.5 * segment.grid.voxelSize());
    setVector(lo - half, e.mutable_bounds_world()->mutable_min());
    setVector(hi + half, e.mutable_bounds_world()->mutable_max());
  }
  stream->send(std::move(extracted));  // moves `e` away
  sendObjectEvents(stream, objectEvents(*report, segment_id));
  return absl::OkStatus();
}

uint64_t ObjectDatabaseService::segmentIdOf(const std::string& session, gsm::Label label) const {
  const auto id = store_->rawSegmentId({session, label});
  return id.ok() ? uint64_t(*id) : 0;
}

void ObjectDatabaseService::sendObjectEvents(IngestStream* stream,
                                             std::vector<v1::ObjectEvent> events) {
  for (v1::ObjectEvent& o : events) {
    v1::IngestResponse event;
    *event.mutable_object() = std::move(o);
    stream->send(std::move(event));
  }
}

Status ObjectDatabaseService::withdraw(LiveSession& session, IngestStream* stream,
                                       gsm::Label label) {
  const auto withdrawn = db_->withdrawSegment(session.name, label);
  if (!withdrawn.ok()) {
    const Status failed = annotate(
        withdrawn.status(), absl::StrFormat("withdrawing segment %d of session %s from the database",
                                            label, session.name));
    return failInsert(stream, failed);
  }
  if (withdrawn->model_id == 0) return absl::OkStatus();  // never inserted
  logger("server")->debug("session {}: segment {} withdrawn from object {} (its label merged "
                          "into another or its voxels taken)",
                          session.name, label, withdrawn->model_id);
  {
    std::lock_guard lock(session.mutex);
    session.counters.set_segments_withdrawn(session.counters.segments_withdrawn() + 1);
    if (withdrawn->removed) {
      session.counters.set_objects_removed(session.counters.objects_removed() + 1);
    }
  }
  if (withdrawn->removed && stream != nullptr) {  // it was the object's only segment
    sendObjectEvents(stream,
                     {removedEvent(withdrawn->model_id, 0, segmentIdOf(session.name, label))});
  }
  return absl::OkStatus();
}

Status ObjectDatabaseService::flush(LiveSession& session) {
  if (session.leaseLost()) return lostLease(session.name);
  if (session.snapshot().frames_received() == 0) {
    retireEmptySession(session);  // it never received a frame: nothing to flush, nothing kept
    return absl::OkStatus();
  }
  if (!session.flush_extracted) {
    for (auto& job : extractSegments(session, true, v1::SegmentExtracted::SESSION_END)) {
      session.flush_jobs.push_back(std::move(job));
    }
    session.flush_extracted = true;
  }
  if (!session.flush_scene_stored) {
    // The final map is stored before the last segments go in: servers that insert other
    // sessions' segments meanwhile verify poses in this session against it (they cannot see this
    // server's live map), as this server does against its own snapshot.
    OBJDB_RETURN_IF_ERROR(store_->putScene(
        session.name, std::make_shared<const tsdf::TsdfLayer>(session.map->tsdf().snapshot()),
        std::make_shared<const gsm::LabelBlocks>(session.map->mainLabelBlocks())));
    session.flush_scene_stored = true;
  }
  const size_t flushed = session.flush_jobs.size();
  while (!session.flush_jobs.empty()) {
    OBJDB_RETURN_IF_ERROR(insert(session, nullptr, session.flush_jobs.front()));
    session.flush_jobs.pop_front();
  }
  const int64_t frames = int64_t(session.snapshot().frames_integrated());
  const gsm::ExtractionCounts counts = session.map->extractionCounts();
  OBJDB_RETURN_IF_ERROR(store_->finishSession(session.name, storage::SessionState::kEnded, frames));
  if (Status stored = store_->storeSessionCounters(session.name, countersJson(session.snapshot()));
      !stored.ok()) {
    logger("server")->warn("session {} ended, but its counters were not stored: {}", session.name,
                           std::string(stored.message()));
  }
  {
    std::lock_guard lock(session.mutex);
    session.state = v1::SESSION_STATE_ENDED;
    session.ended_unix_s = nowUnixSeconds();
  }
  // The map is stored; free its memory (the store serves its scene from now on).
  session.map.reset();
  session.segmenter.reset();
  {
    std::lock_guard lock(session.mutex);
    session.scene.reset();
  }
  session.frame_indices = {};
  logger("server")->info(
      "session {} ended: {} frames, {} segments flushed at the end; objects extracted {} times "
      "for the first time, {} again, {} updated but unchanged (kept), {} held back as flicker, {} "
      "withdrawn",
      session.name, frames, flushed, counts.first, counts.again, counts.unchanged,
      counts.unconfirmed, counts.withdrawn);
  releaseLease(session.name);
  forgetEndedSessions();
  return absl::OkStatus();
}

void ObjectDatabaseService::forgetEndedSessions() {
  std::lock_guard lock(mutex_);
  std::vector<std::pair<double, std::string>> ended;  // (ended at, name)
  for (const auto& [name, session] : sessions_) {
    std::lock_guard session_lock(session->mutex);
    if (session->state == v1::SESSION_STATE_ENDED && !session->streaming) {
      ended.emplace_back(session->ended_unix_s, name);
    }
  }
  const size_t kept = options_.ended_sessions_kept;
  if (ended.size() <= kept) return;
  std::sort(ended.begin(), ended.end());
  for (size_t i = 0; i + kept < ended.size(); ++i) sessions_.erase(ended[i].second);
}

grpc::ServerBidiReactor<v1::IngestRequest, v1::IngestResponse>* ObjectDatabaseService::Ingest(
    grpc::CallbackServerContext* context) {
  if (const Status allowed = authorize(context, options_.token); !allowed.ok()) {
    return new RefusedCall<grpc::ServerBidiReactor<v1::IngestRequest, v1::IngestResponse>>(
        toGrpcStatus(allowed));
  }
  return new IngestReactor(context, options_.frame_queue,
                           [this](std::shared_ptr<IngestStream> stream) {
                             startWorker([this, stream] { runStream(stream); });
                           });
}

grpc::ServerUnaryReactor* ObjectDatabaseService::EndSession(grpc::CallbackServerContext* context,
                                                            const v1::EndSessionRequest* request,
                                                            v1::EndSessionResponse* response) {
  if (const Status allowed = authorize(context, options_.token); !allowed.ok()) {
    return finishUnary(context, allowed);
  }
  const std::string& name = request->session_name();
  std::shared_ptr<LiveSession> session = liveSession(name);
  if (!session) {
    // Checked before the store is read: once off the list, its recovery is committed.
    if (Status recovering = checkNotRecovering(name); !recovering.ok()) {
      return finishUnary(context, recovering);
    }
    return answerOffThread(context, [this, name, response]() -> Status {
      OBJDB_ASSIGN_OR_RETURN(const std::vector<storage::SessionInfo> stored, store_->sessions());
      for (const auto& s : stored) {
        if (s.name != name) continue;
        if (s.state != storage::SessionState::kEnded) {
          OBJDB_ASSIGN_OR_RETURN(const int64_t saved_frames, store_->savedMapFrames(name));
          if (saved_frames >= 0) return recoveryFailed(name, saved_frames);
          OBJDB_ASSIGN_OR_RETURN(const std::shared_ptr<const tsdf::TsdfLayer> scene,
                                 store_->scene(name));
          if (scene != nullptr) {
            return absl::FailedPreconditionError(absl::StrFormat(
                "session %s was not ended before the server stopped; it was ended at the next "
                "start from its map saved after %d frames (its segments are in the database, its "
                "scene is stored); the frames after it were lost",
                name, s.frames));
          }
          return absl::FailedPreconditionError(absl::StrFormat(
              "session %s was not ended before the server stopped; its map was not kept (the "
              "segments inserted before are in the database), so it cannot be flushed any more",
              name));
        }
        v1::SessionSummary& summary = *response->mutable_summary();
        summary.set_session_name(name);
        summary.set_state(v1::SESSION_STATE_ENDED);
        (void)countersFromJson(s.counters_json, summary.mutable_counters());
        summary.mutable_counters()->set_frames_integrated(uint64_t(s.frames));
        OBJDB_ASSIGN_OR_RETURN(const std::vector<uint64_t> ids, objectsOf(name));
        for (uint64_t id : ids) summary.add_object_ids(id);
        return absl::OkStatus();
      }
      return absl::NotFoundError(absl::StrFormat("no session named \"%s\"", name));
    });
  }
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  // On the database thread, after every segment queued before it: flush once, then answer. A
  // second call queued behind the flush answers with the ended session's summary.
  auto job = [this, session, reactor, response] {
    Status status = absl::OkStatus();
    if (!session->ended()) {
      logger("server")->info("session {}: EndSession: flushing its map into the database",
                             session->name);
      status = flush(*session);
    }
    if (status.ok()) {
      auto summary = summaryOf(*session);
      if (summary.ok()) {
        *response->mutable_summary() = *std::move(summary);
      } else {
        status = summary.status();
      }
    }
    reactor->Finish(toGrpcStatus(status));
  };
  {
    std::lock_guard lock(session->mutex);
    if (session->streaming) {
      // A stream already cancelled only waits for its frame worker to stop: queue behind it.
      bool cancelled = false;
      if (std::shared_ptr<IngestStream> stream = session->stream.lock()) {
        std::lock_guard stream_lock(stream->mutex);
        cancelled = stream->cancelled;
      }
      if (!cancelled) {
        reactor->Finish(toGrpcStatus(absl::FailedPreconditionError(absl::StrFormat(
            "session %s still has its Ingest stream open; half-close it (WritesDone) and read it "
            "to the end first",
            name))));
        return reactor;
      }
      session->end_queued = true;  // not resumed any more
      session->after_stream.push_back(std::move(job));
      return reactor;
    }
    session->end_queued = true;
  }
  database_queue_->push(std::move(job));
  return reactor;
}

}  // namespace objdb::server
