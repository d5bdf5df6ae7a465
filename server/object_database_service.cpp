#include "server/object_database_service.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <condition_variable>
#include <deque>
#include <filesystem>
#include <future>
#include <optional>
#include <set>
#include <utility>

#include <nlohmann/json.hpp>

#include "absl/strings/numbers.h"
#include "absl/strings/str_split.h"
#include "absl/strings/str_format.h"
#include "core/common/logging.h"
#include "core/common/params_io.h"
#include "core/completion/scene_completion.h"
#include "core/database/object_database.h"
#include "core/gsm/gsm.h"
#include "core/segmentation/depth_segmenter.h"
#include "core/tsdf/mesh_extraction.h"
#include "server/auth.h"
#include "server/job_queue.h"
#include "server/proto_convert.h"
#include "server/status_convert.h"
#include "storage/model_settings.h"

namespace objdb::server {

namespace {

constexpr uint32_t kDefaultPageSize = 100;
constexpr uint32_t kMaxPageSize = 1000;
constexpr size_t kMaxSessionName = 128;
constexpr size_t kMaxClientInfo = 256;
// Camera positions farther from the world origin are refused: voxel block indices stay small.
constexpr double kMaxWorldExtentM = 10000.0;

double nowUnixSeconds() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

grpc::ServerUnaryReactor* finishUnary(grpc::CallbackServerContext* context, const Status& status) {
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  reactor->Finish(toGrpcStatus(status));
  return reactor;
}

// Ends a streaming call at once with `status` (a refused call: no token, wrong token).
template <typename Reactor>
class RefusedCall final : public Reactor {
 public:
  explicit RefusedCall(const grpc::Status& status) { this->Finish(status); }
  void OnDone() override { delete this; }
};

// The call's bearer token against the server's (auth::checkBearer); the first thing every
// handler does.
Status authorize(const grpc::CallbackServerContext* context, const std::string& token) {
  if (token.empty()) return absl::OkStatus();
  const auto& metadata = context->client_metadata();
  const auto it = metadata.find(auth::kAuthorizationKey);
  if (it == metadata.end()) return auth::checkBearer(token, nullptr);
  const std::string value(it->second.data(), it->second.size());
  return auth::checkBearer(token, &value);
}

Status checkSessionName(const std::string& name) {
  if (name.empty() || name.size() > kMaxSessionName) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "header.session_name has %d characters; it must have 1..%d", name.size(), kMaxSessionName));
  }
  for (unsigned char c : name) {
    if (!(std::isalnum(c) || c == '.' || c == '_' || c == '-')) {
      return absl::InvalidArgumentError(absl::StrFormat(
          "header.session_name \"%s\" holds '%c'; use only A-Z a-z 0-9 . _ -", name, c));
    }
  }
  return absl::OkStatus();
}

// Sections a session may override: they shape its own map. The rest describes the shared
// object database and is the server's (--config).
bool perSessionSection(const std::string& section) {
  return section == "segmentation" || section == "tsdf" || section == "gsm";
}

// Page tokens: "<kind>.<last id>.<filter hash>", opaque to clients.
std::string pageToken(char kind, int64_t last_id, uint64_t filter) {
  return absl::StrFormat("%c.%d.%x", kind, last_id, filter);
}

StatusOr<int64_t> parsePageToken(const std::string& token, char kind, uint64_t filter) {
  if (token.empty()) return int64_t{0};
  const std::vector<std::string> parts = absl::StrSplit(token, '.');
  int64_t last = 0;
  uint64_t hash = 0;
  if (parts.size() != 3 || parts[0].size() != 1 || parts[0][0] != kind ||
      !absl::SimpleAtoi(parts[1], &last) || last < 0 || !absl::SimpleHexAtoi(parts[2], &hash)) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "page_token \"%s\" is not a token this call returned; start with an empty token", token));
  }
  if (hash != filter) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "page_token \"%s\" belongs to a listing with another filter; start again with an empty "
        "token",
        token));
  }
  return last;
}

uint32_t pageSize(uint32_t requested) {
  return requested == 0 ? kDefaultPageSize : std::min(requested, kMaxPageSize);
}

// Whether a stored raw segment is `segment`: the same pose (hence the same grid origin), the same
// voxels (both lists in extractRawSegment's order) and the same TSDF values around them. Then
// re-inserting it would change nothing; a label observed again after its extraction has new TSDF
// values even where its voxels stayed.
bool sameSegment(const database::RawSegmentRecord& stored, const gsm::RawSegment& segment) {
  if (stored.grid == nullptr || stored.voxels != segment.label_voxels ||
      stored.grid->voxelSize() != segment.grid.voxelSize() ||
      stored.grid->voxelsPerSide() != segment.grid.voxelsPerSide() ||
      stored.grid->numBlocks() != segment.grid.numBlocks() ||
      !stored.T_world_segment.isApprox(segment.T_world_segment, 1e-9)) {
    return false;
  }
  for (const auto& [index, block] : segment.grid.blocks()) {
    const tsdf::TsdfBlock* other = stored.grid->block(index);
    if (other == nullptr) return false;
    for (size_t i = 0; i < block->voxels().size(); ++i) {
      const tsdf::TsdfVoxel& a = block->voxels()[i];
      const tsdf::TsdfVoxel& b = other->voxels()[i];
      if (a.distance != b.distance || a.weight != b.weight) return false;
    }
  }
  return true;
}

// How long after its stream went a session still open gets its last frames saved.
constexpr std::chrono::milliseconds kIdleSaveDelay{5000};

int64_t fileBytes(const std::string& path) {
  int64_t total = 0;
  for (const char* suffix : {"", "-wal", "-shm"}) {
    std::error_code ec;
    const auto size = std::filesystem::file_size(path + suffix, ec);
    if (!ec) total += int64_t(size);
  }
  return total;
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Sessions and streams
// ---------------------------------------------------------------------------------------------

// A raw segment waiting for the database, with why it was extracted.
struct RawSegmentJob {
  gsm::RawSegment segment;
  v1::SegmentExtracted::Reason reason = v1::SegmentExtracted::IDLE;
  uint64_t last_frame_index = 0;  // client index of the last frame that observed it
};

// One session with a map in memory: from its header until EndSession.
struct LiveSession {
  std::string name;
  Intrinsics intrinsics;
  Params params;
  std::string client_info;
  double started_unix_s = 0.0;

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
  std::deque<RawSegmentJob> flush_jobs;

  std::mutex mutex;  // guards what follows
  v1::SessionState state = v1::SESSION_STATE_OPEN;
  bool streaming = true;  // its Ingest stream (frame worker) is still running
  double ended_unix_s = 0.0;
  v1::SessionCounters counters;
  std::weak_ptr<IngestStream> stream;
  std::chrono::steady_clock::time_point stream_gone;  // when `streaming` became false
  bool end_queued = false;  // the server queued its own end (idle too long, or stopping)
  // Database jobs to queue when the frame worker is done (EndSession of an interrupted stream).
  std::vector<std::function<void()>> after_stream;

  // Saving the map (maybeSaveMap): the frame worker's clock, a save waiting in the queue, and
  // the frame count of the last save written.
  std::chrono::steady_clock::time_point map_saved_at{};
  std::atomic<bool> map_save_pending{false};
  std::atomic<int64_t> map_saved_frames{0};
  int64_t idle_save_tried = -1;  // frame count the janitor last queued a save for (mutex)

  v1::SessionCounters snapshot() {
    std::lock_guard lock(mutex);
    return counters;
  }
  bool ended() {
    std::lock_guard lock(mutex);
    return state == v1::SESSION_STATE_ENDED;
  }
};

// The jobs for segments extracted from `session`'s map (on the thread that owns the map).
std::vector<RawSegmentJob> jobsOf(const LiveSession& session, std::vector<gsm::RawSegment> segments,
                                  v1::SegmentExtracted::Reason reason);

class IngestReactor;

// What the reactor (gRPC threads) and the frame worker share. Reactor calls happen under the
// mutex and only while `reactor` is set (OnDone clears it).
struct IngestStream {
  std::recursive_mutex mutex;
  std::condition_variable_any changed;
  IngestReactor* reactor = nullptr;
  bool header_seen = false;
  v1::SessionHeader header;               // the first message, handed to the frame worker
  std::shared_ptr<LiveSession> session;   // set by the frame worker once the session is open
  std::deque<v1::Frame> inbox;
  bool reads_paused = false;
  bool input_ended = false;  // the client half-closed
  bool cancelled = false;    // cancelled, or ended by an error: stop working
  bool finished = false;     // Finish was called (or is pending behind writes)
  std::deque<v1::IngestResponse> outbox;
  bool writing = false;
  std::chrono::steady_clock::time_point last_write_done{};  // the client's last read (progress)
  std::optional<grpc::Status> finish_pending;

  void send(v1::IngestResponse response);
  // Frame worker, before each frame: waits while `max_pending` events wait for the client. False
  // when the stream was cancelled or finished meanwhile, or when the client read nothing for
  // `timeout` (counted from the later of the wait's start and its last read): then the stream is
  // finished with RESOURCE_EXHAUSTED (delivered after the event being written, whenever the
  // client reads again), and the events behind that one and the frames not yet taken are dropped.
  bool waitForReader(size_t max_pending, std::chrono::milliseconds timeout,
                     const std::string& session);
  void finish(const grpc::Status& status);
  void resumeReading();
};

class IngestReactor final : public grpc::ServerBidiReactor<v1::IngestRequest, v1::IngestResponse> {
 public:
  IngestReactor(ObjectDatabaseService* service, grpc::CallbackServerContext* context)
      : service_(service), context_(context), stream_(std::make_shared<IngestStream>()) {
    stream_->reactor = this;
    StartRead(&request_);
  }

  void OnReadDone(bool ok) override {
    // The frame worker starts outside the stream's mutex: startWorker takes the service's mutex,
    // which the janitor holds while it takes a session's, and EndSession takes a stream's mutex
    // while it holds a session's (one lock order: service, session, stream).
    if (takeRead(ok)) {
      service_->startWorker([service = service_, stream = stream_] { service->runStream(stream); });
    }
  }

  void OnWriteDone(bool ok) override {
    std::lock_guard lock(stream_->mutex);
    stream_->outbox.pop_front();
    stream_->last_write_done = std::chrono::steady_clock::now();
    stream_->changed.notify_all();  // a frame worker may wait for room (waitForReader)
    if (!ok) {  // the client is gone
      stream_->outbox.clear();
      stream_->cancelled = true;
      stream_->changed.notify_all();
    }
    if (!stream_->outbox.empty()) {
      StartWrite(&stream_->outbox.front());
      return;
    }
    stream_->writing = false;
    if (stream_->finish_pending) {
      Finish(*stream_->finish_pending);
      stream_->finish_pending.reset();
    }
  }

  void OnCancel() override {
    std::lock_guard lock(stream_->mutex);
    stream_->cancelled = true;
    // Without a header there is no worker to end the call: gRPC needs Finish even when cancelled.
    if (!stream_->header_seen) stream_->finish(grpc::Status(grpc::StatusCode::CANCELLED, "cancelled"));
    stream_->changed.notify_all();
  }

  void OnDone() override {
    {
      std::lock_guard lock(stream_->mutex);
      stream_->reactor = nullptr;
      stream_->cancelled = true;
      stream_->changed.notify_all();
    }
    delete this;
  }

  void read() { StartRead(&request_); }

 private:
  // The read's effect on the stream, under its mutex; true when the header came and the frame
  // worker is to be started.
  bool takeRead(bool ok) {
    std::lock_guard lock(stream_->mutex);
    if (stream_->finished) return false;
    if (!ok || stream_->cancelled) {
      if (!stream_->header_seen) {  // no worker to end the call: end it here
        stream_->finish(stream_->cancelled || context_->IsCancelled()
                            ? grpc::Status(grpc::StatusCode::CANCELLED, "cancelled")
                            : grpc::Status(grpc::StatusCode::FAILED_PRECONDITION,
                                           "the stream ended before its SessionHeader"));
      } else if (!ok && context_->IsCancelled()) {
        stream_->cancelled = true;
      } else if (!ok) {
        stream_->input_ended = true;
      }
      stream_->changed.notify_all();
      return false;
    }
    if (!stream_->header_seen) {
      if (!request_.has_header()) {
        stream_->finish(grpc::Status(grpc::StatusCode::FAILED_PRECONDITION,
                                     "the first message of an Ingest stream must be a "
                                     "SessionHeader; a frame came first"));
        return false;
      }
      // The frame worker opens the session (checks, store write): no waiting on gRPC's threads.
      stream_->header_seen = true;
      stream_->header = request_.header();
      StartRead(&request_);
      return true;
    }
    if (request_.has_header()) {
      stream_->cancelled = true;
      stream_->finish(grpc::Status(grpc::StatusCode::FAILED_PRECONDITION,
                                   "a second SessionHeader on the stream of session " +
                                       stream_->header.session_name() +
                                       "; one stream is one session"));
      stream_->changed.notify_all();
      return false;
    }
    stream_->inbox.push_back(std::move(*request_.mutable_frame()));
    stream_->changed.notify_all();
    if (stream_->inbox.size() < service_->options_.frame_queue) {
      StartRead(&request_);
    } else {
      stream_->reads_paused = true;  // the worker resumes reading when it takes a frame
    }
    return false;
  }

  ObjectDatabaseService* service_;
  grpc::CallbackServerContext* context_;
  std::shared_ptr<IngestStream> stream_;
  v1::IngestRequest request_;
};

void IngestStream::send(v1::IngestResponse response) {
  std::lock_guard lock(mutex);
  if (reactor == nullptr || finished) return;
  outbox.push_back(std::move(response));
  if (!writing) {
    writing = true;
    reactor->StartWrite(&outbox.front());
  }
}

bool IngestStream::waitForReader(size_t max_pending, std::chrono::milliseconds timeout,
                                 const std::string& session) {
  std::unique_lock lock(mutex);
  const auto room = [&] { return cancelled || finished || outbox.size() < max_pending; };
  // The timeout runs from the later of the wait's start and the client's last read.
  const auto waiting_since = std::chrono::steady_clock::now();
  const auto give_up = [&] { return std::max(waiting_since, last_write_done) + timeout; };
  while (!room()) {
    if (changed.wait_until(lock, give_up(), room)) break;
    if (give_up() > std::chrono::steady_clock::now()) continue;  // the client read meanwhile
    const size_t pending = outbox.size();
    // The front event is being written (gRPC holds it); the others are never sent, and the
    // frames not yet taken are never fused.
    if (writing && pending > 1) outbox.erase(outbox.begin() + 1, outbox.end());
    inbox.clear();
    cancelled = true;
    const double seconds = std::chrono::duration<double>(timeout).count();
    finish(grpc::Status(
        grpc::StatusCode::RESOURCE_EXHAUSTED,
        absl::StrFormat("the client read none of the %d events waiting on the Ingest stream of "
                        "session %s for %g s; stream ended (the session is kept, "
                        "interrupted: EndSession stores it)",
                        pending, session, seconds)));
    changed.notify_all();
    logger("server")->warn("session {}: the client has read none of its {} waiting events for "
                           "{} s; ending its stream",
                           session, pending, seconds);
    return false;
  }
  return !cancelled && !finished;
}

void IngestStream::finish(const grpc::Status& status) {
  std::lock_guard lock(mutex);
  if (reactor == nullptr || finished) return;
  finished = true;
  if (writing) {
    finish_pending = status;
  } else {
    reactor->Finish(status);
  }
}

void IngestStream::resumeReading() {
  std::lock_guard lock(mutex);
  if (reactor == nullptr || finished || !reads_paused) return;
  reads_paused = false;
  reactor->read();
}

// ---------------------------------------------------------------------------------------------
// Service
// ---------------------------------------------------------------------------------------------

StatusOr<std::unique_ptr<ObjectDatabaseService>> ObjectDatabaseService::create(
    const ServiceOptions& options, storage::SqliteStore* store) {
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

Status ObjectDatabaseService::startRecovery() {
  std::vector<storage::SessionInfo> unended;
  unended.swap(unended_);
  // Those with a saved map are ended from it (on the database thread, while the server serves);
  // the others lost their maps. At the first store error nothing more is written.
  std::vector<storage::SessionInfo> queued;
  Status status = absl::OkStatus();
  for (const auto& s : unended) {
    auto saved_frames = store_->savedMapFrames(s.name);
    status = saved_frames.status();
    if (status.ok() && s.state == storage::SessionState::kOpen) {
      if (*saved_frames < 0) {
        logger("server")->warn("session {} was still open when the server last stopped and has "
                               "no saved map; its map is lost (segments inserted before stay): "
                               "marking it interrupted",
                               s.name);
      }
      // Interrupted at once (it streams no more), whatever its recovery below does.
      status = store_->finishSession(s.name, storage::SessionState::kInterrupted, s.frames);
    }
    if (!status.ok()) {
      status = annotate(status, absl::StrFormat("session %s", s.name));
      queued.clear();
      break;
    }
    if (*saved_frames >= 0) queued.push_back(s);
  }
  {
    std::lock_guard lock(mutex_);
    for (const auto& s : unended) recovering_.erase(s.name);
    for (const auto& s : queued) recovering_.insert(s.name);
  }
  for (const auto& s : queued) {
    database_queue_->push([this, s] {
      const Status recovered = recoverSession(s);
      if (!recovered.ok()) {
        logger("server")->error("session {} could not be ended from its saved map (tried again "
                                "at the next start): {}",
                                s.name, std::string(recovered.message()));
      }
      std::lock_guard lock(mutex_);
      recovering_.erase(s.name);
    });
  }
  return status;
}

Params ObjectDatabaseService::storedSessionParams(const storage::SessionInfo& stored) const {
  Params params = options_.params;
  if (Status applied = applyParamsJson(stored.params_json, &params); !applied.ok()) {
    params = options_.params;
  }
  return params;
}

Status ObjectDatabaseService::recoveryFailed(const std::string& name, int64_t saved_frames) {
  return absl::FailedPreconditionError(absl::StrFormat(
      "session %s was not ended before the server stopped; ending it from its map saved after %d "
      "frames failed at this start (the server's log says why); the next start tries again",
      name, saved_frames));
}

Status ObjectDatabaseService::checkNotRecovering(const std::string& name) {
  std::lock_guard lock(mutex_);
  if (recovering_.count(name) == 0) return absl::OkStatus();
  return absl::UnavailableError(absl::StrFormat(
      "session %s was not ended before the server stopped and is being ended from its saved map; "
      "try again shortly",
      name));
}

Status ObjectDatabaseService::recoverSession(const storage::SessionInfo& stored) {
  OBJDB_ASSIGN_OR_RETURN(const storage::SavedMap saved, store_->savedMap(stored.name));
  if (saved.map == nullptr) return absl::OkStatus();
  const Params params = storedSessionParams(stored);
  logger("server")->warn("session {} was not ended when the server last stopped: ending it from "
                         "its map saved after {} frames (the frames after it are lost)",
                         stored.name, saved.frames);
  const gsm::LabelBlocks no_labels;
  const std::vector<gsm::RawSegment> segments = gsm::extractLabelled(
      *saved.map, saved.labels ? *saved.labels : no_labels, params.gsm.min_label_voxels,
      int(std::ceil(params.tsdf.truncation_voxels)), saved.frames);
  size_t inserted = 0, unchanged = 0;
  for (const gsm::RawSegment& segment : segments) {
    // A label extracted (and inserted) before the save and not changed since is already there.
    auto earlier = store_->rawSegment({stored.name, segment.label});
    if (earlier.ok() && sameSegment(**earlier, segment)) {
      ++unchanged;
      continue;
    }
    if (!earlier.ok() && !absl::IsNotFound(earlier.status())) return earlier.status();
    auto report = db_->insertSegment(stored.name, segment);
    if (!report.ok()) {
      if (absl::IsFailedPrecondition(report.status()) ||
          absl::IsInvalidArgument(report.status())) {
        continue;  // a segment the database cannot take (no surface at the mesh weight)
      }
      return annotate(report.status(), absl::StrFormat("inserting segment %d of session %s",
                                                       segment.label, stored.name));
    }
    ++inserted;
  }
  OBJDB_RETURN_IF_ERROR(store_->putScene(stored.name, saved.map, saved.labels));
  OBJDB_RETURN_IF_ERROR(
      store_->finishSession(stored.name, storage::SessionState::kInterrupted, saved.frames));
  OBJDB_RETURN_IF_ERROR(store_->dropSavedMap(stored.name));
  logger("server")->info("session {} ended from its saved map: {} frames, {} segments inserted, "
                         "{} unchanged since they were inserted; state interrupted",
                         stored.name, saved.frames, inserted, unchanged);
  return absl::OkStatus();
}

ObjectDatabaseService::ObjectDatabaseService(const ServiceOptions& options,
                                             storage::SqliteStore* store,
                                             std::unique_ptr<database::ObjectDatabase> db)
    : options_(options),
      store_(store),
      db_(std::move(db)),
      database_queue_(std::make_unique<JobQueue>(options.segment_queue)) {
  if (options_.auto_end_after.count() > 0) janitor_ = std::thread([this] { endIdleSessions(); });
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
      // its last save is saved too, a few seconds after the stream went.
      if (!session->streaming && !session->end_queued &&
          session->state != v1::SESSION_STATE_ENDED && options_.save_map_every.count() > 0 &&
          !session->map_save_pending &&
          session->map_saved_frames < int64_t(session->counters.frames_integrated()) &&
          session->idle_save_tried < int64_t(session->counters.frames_integrated()) &&
          now - session->stream_gone >=
              std::min<std::chrono::milliseconds>(options_.save_map_every, kIdleSaveDelay)) {
        session->map_save_pending = true;
        session->idle_save_tried = int64_t(session->counters.frames_integrated());  // once
        database_queue_->push([this, session = session] { saveIdleMap(session); });
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
  if (janitor_.joinable()) janitor_.join();
  for (auto& w : workers) w.thread.join();
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
      if (endByServer(*session).ok()) return;
      (void)store_->finishSession(session->name, storage::SessionState::kInterrupted,
                                  int64_t(session->snapshot().frames_integrated()));
    });
  }
  database_queue_.reset();  // runs what is queued, then stops
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
  if (open < options_.max_open_sessions) return absl::OkStatus();
  return absl::ResourceExhaustedError(absl::StrFormat(
      "too many sessions with a map in memory (%d): end some with EndSession, or start the "
      "server with a larger --max-sessions",
      open));
}

StatusOr<std::shared_ptr<LiveSession>> ObjectDatabaseService::openSession(
    const v1::SessionHeader& header, const std::shared_ptr<IngestStream>& stream) {
  {
    // Refused before a map is built (checked again when the session is published).
    std::lock_guard lock(mutex_);
    OBJDB_RETURN_IF_ERROR(checkSessionLimit());
  }
  OBJDB_RETURN_IF_ERROR(checkSessionName(header.session_name()));
  if (header.client_info().size() > kMaxClientInfo) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "header.client_info has %d characters; at most %d", header.client_info().size(),
        kMaxClientInfo));
  }
  if (!header.has_intrinsics()) {
    return absl::InvalidArgumentError("header.intrinsics is missing");
  }
  auto session = std::make_shared<LiveSession>();
  session->name = header.session_name();
  session->client_info = header.client_info();
  OBJDB_ASSIGN_OR_RETURN(session->intrinsics, fromProto(header.intrinsics(), "header.intrinsics"));
  session->params = options_.params;
  if (!header.params_json().empty()) {
    const nlohmann::json overrides = nlohmann::json::parse(header.params_json(), nullptr, false);
    if (overrides.is_discarded() || !overrides.is_object()) {
      return absl::InvalidArgumentError("header.params_json is not a JSON object");
    }
    for (const auto& [section, value] : overrides.items()) {
      if (!perSessionSection(section)) {
        return absl::InvalidArgumentError(absl::StrFormat(
            "header.params_json sets \"%s\", which describes the shared object database; only "
            "\"segmentation\", \"tsdf\" and \"gsm\" may differ per session (set the rest in the "
            "server's --config)",
            section));
      }
    }
    if (Status applied = applyParamsJson(header.params_json(), &session->params); !applied.ok()) {
      return absl::InvalidArgumentError(absl::StrCat("header.params_json: ", applied.message()));
    }
  }
  OBJDB_ASSIGN_OR_RETURN(const std::vector<storage::SessionInfo> stored, store_->sessions());
  // The models of this session must be described as the database's are (and as the server's).
  storage::SessionInfo server_settings;
  server_settings.name = "(the server's --config)";
  server_settings.params_json = paramsToJson(options_.params);
  for (const std::vector<storage::SessionInfo>& against : {stored, {server_settings}}) {
    if (Status same = storage::checkModelSettings(against, session->params); !same.ok()) {
      return absl::InvalidArgumentError(absl::StrCat("header.params_json: ", same.message()));
    }
  }
  OBJDB_ASSIGN_OR_RETURN(
      segmentation::DepthSegmenter segmenter,
      segmentation::DepthSegmenter::create(session->params.segmentation, session->intrinsics));
  session->segmenter.emplace(std::move(segmenter));
  OBJDB_ASSIGN_OR_RETURN(gsm::Gsm map,
                         gsm::Gsm::create(session->params.tsdf, session->params.gsm,
                                          session->intrinsics, options_.integration_threads));
  session->map.emplace(std::move(map));

  std::lock_guard lock(mutex_);
  if (stopped_) return absl::UnavailableError("the server is shutting down");
  OBJDB_RETURN_IF_ERROR(checkSessionLimit());
  storage::SessionInfo info;
  info.name = session->name;
  info.intrinsics_json = storage::intrinsicsJson(session->intrinsics);
  info.params_json = paramsToJson(session->params);
  // ALREADY_EXISTS when the database has a session of that name.
  OBJDB_RETURN_IF_ERROR(store_->beginSession(info).status());
  session->started_unix_s = nowUnixSeconds();
  session->stream = stream;  // before it is published: EndSession looks at the stream
  sessions_[session->name] = session;
  logger("server")->info("session {} opened ({}x{}, client \"{}\")", session->name,
                         session->intrinsics.width, session->intrinsics.height,
                         session->client_info);
  return session;
}

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
  auto opened = openSession(header, stream);
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
  LiveSession& session = **opened;
  bool ended_cleanly = false;
  while (true) {
    // Backpressure from a client that does not read: no more frames until it does.
    if (!stream->waitForReader(options_.max_pending_events, options_.slow_reader_timeout,
                               session.name)) {
      break;
    }
    v1::Frame frame;
    {
      std::unique_lock lock(stream->mutex);
      stream->changed.wait(lock, [&] {
        return stream->cancelled || !stream->inbox.empty() || stream->input_ended;
      });
      if (stream->cancelled) break;
      if (stream->inbox.empty()) {
        ended_cleanly = true;
        break;
      }
      frame = std::move(stream->inbox.front());
      stream->inbox.pop_front();
      stream->resumeReading();
    }
    processFrame(stream, frame);
  }
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
  stream->finish(grpc::Status(grpc::StatusCode::CANCELLED, "the Ingest stream was interrupted"));
  logger("server")->warn("session {}: stream interrupted; EndSession can still flush its map",
                         session.name);
}

void ObjectDatabaseService::endStreaming(const std::shared_ptr<LiveSession>& session,
                                         bool interrupted) {
  if (interrupted) {
    // Stored on the database thread, so that it lands before any EndSession flush queued later.
    database_queue_->push([this, session] {
      if (session->ended()) return;
      (void)store_->finishSession(session->name, storage::SessionState::kInterrupted,
                                  int64_t(session->snapshot().frames_integrated()));
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
                                         const v1::Frame& frame) {
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
    if (session.has_frame && frame.index() <= session.last_index) {
      return absl::InvalidArgumentError(absl::StrFormat(
          "frame.index %d is not above the previous frame's %d", frame.index(), session.last_index));
    }
    if (!std::isfinite(frame.timestamp_s()) ||
        (session.has_frame && frame.timestamp_s() <= session.last_timestamp)) {
      return absl::InvalidArgumentError(absl::StrFormat(
          "frame.timestamp_s %g is not finite or not above the previous frame's %g",
          frame.timestamp_s(), session.last_timestamp));
    }
    if (!frame.has_t_world_camera()) {
      return absl::InvalidArgumentError("frame.T_world_camera is missing");
    }
    OBJDB_ASSIGN_OR_RETURN(const Transform T_world_camera,
                           fromProto(frame.t_world_camera(), "frame.T_world_camera"));
    if (T_world_camera.translation().norm() > kMaxWorldExtentM) {
      return absl::InvalidArgumentError(absl::StrFormat(
          "frame.T_world_camera is %g m from the world origin; at most %g m (a session's world "
          "frame should be near where it was recorded)",
          T_world_camera.translation().norm(), kMaxWorldExtentM));
    }
    if (!frame.has_depth()) return absl::InvalidArgumentError("frame.depth is missing");
    DepthCounts counts;
    OBJDB_ASSIGN_OR_RETURN(const DepthImage depth,
                           decodeDepth(frame.depth(), session.intrinsics, &counts));
    std::optional<ColorImage> color;
    if (frame.has_color()) {
      OBJDB_ASSIGN_OR_RETURN(color, decodeColor(frame.color(), depth.width, depth.height));
    }
    const ColorImage* color_ptr = color ? &*color : nullptr;
    OBJDB_ASSIGN_OR_RETURN(const segmentation::SegmentationResult segments,
                           session.segmenter->segment(depth, color_ptr));
    OBJDB_ASSIGN_OR_RETURN(const gsm::GsmFrameResult fused,
                           session.map->integrate(depth, segments.labels, T_world_camera, color_ptr));
    session.has_frame = true;
    session.last_index = frame.index();
    session.last_timestamp = frame.timestamp_s();
    session.frame_indices.push_back(frame.index());
    ack.set_accepted(true);
    v1::FrameCounters& c = *ack.mutable_frame();
    c.set_valid_pixels(uint32_t(fused.tsdf.points_used));
    c.set_missing_pixels(counts.missing);
    c.set_invalid_pixels(counts.invalid);
    c.set_out_of_range_pixels(uint32_t(fused.tsdf.out_of_range));
    c.set_segments(uint32_t(segments.segments.size()));
    std::lock_guard lock(session.mutex);
    session.counters.set_frames_integrated(session.counters.frames_integrated() + 1);
    *ack.mutable_session() = session.counters;
    return absl::OkStatus();
  };
  if (Status processed = run(); !processed.ok()) reject(processed);
  const bool accepted = ack.accepted();
  stream.send(std::move(response));  // moves the ack away
  if (!accepted) return;
  std::vector<RawSegmentJob> jobs =
      jobsOf(session, session.map->extractIdle(), v1::SegmentExtracted::IDLE);
  if (!jobs.empty()) queueInserts(stream_ptr->session, stream_ptr, std::move(jobs), true);
  maybeSaveMap(stream_ptr->session);
}

// A copy of a live map to save, made by the thread that owns the map.
struct MapCopy {
  std::shared_ptr<const tsdf::TsdfLayer> map;
  std::shared_ptr<const gsm::LabelBlocks> labels;
  int64_t frames = 0;
  double copy_ms = 0.0;
};

namespace {

MapCopy copyMap(const gsm::Gsm& map) {
  const auto start = std::chrono::steady_clock::now();
  MapCopy copy{std::make_shared<const tsdf::TsdfLayer>(map.tsdf().clone()),
               std::make_shared<const gsm::LabelBlocks>(map.mainLabelBlocks()), map.frames()};
  copy.copy_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  return copy;
}

}  // namespace

void ObjectDatabaseService::maybeSaveMap(const std::shared_ptr<LiveSession>& session) {
  if (options_.save_map_every.count() <= 0) return;
  const auto now = std::chrono::steady_clock::now();
  if (session->map_saved_at == std::chrono::steady_clock::time_point{}) {
    session->map_saved_at = now;  // the first frame starts the clock
    return;
  }
  if (now - session->map_saved_at < options_.save_map_every || session->map_save_pending) return;
  session->map_saved_at = now;
  session->map_save_pending = true;
  // Behind the inserts queued before it (waiting when the queue is full, like them).
  database_queue_->pushWaiting(
      [this, session, copy = copyMap(*session->map)] { writeSavedMap(session, copy); });
}

void ObjectDatabaseService::saveIdleMap(const std::shared_ptr<LiveSession>& session) {
  // The stream is gone: the map is the database thread's now (flush frees it once ended).
  if (!session->map) {
    session->map_save_pending = false;
    return;
  }
  writeSavedMap(session, copyMap(*session->map));
}

void ObjectDatabaseService::writeSavedMap(const std::shared_ptr<LiveSession>& session,
                                          const MapCopy& copy) {
  if (!session->ended()) {
    const auto start = std::chrono::steady_clock::now();
    const Status saved = store_->putSavedMap(session->name, copy.frames, *copy.map, *copy.labels);
    if (saved.ok()) {
      session->map_saved_frames = copy.frames;
      logger("server")->info(
          "session {}: map saved after {} frames ({} blocks; copied in {:.0f} ms, written in "
          "{:.0f} ms)",
          session->name, copy.frames, copy.map->numBlocks(), copy.copy_ms,
          std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
              .count());
    } else {
      logger("server")->warn("session {}: saving its map failed (a crash would lose more): {}",
                             session->name, std::string(saved.message()));
    }
  }
  session->map_save_pending = false;
}

std::vector<RawSegmentJob> jobsOf(const LiveSession& session, std::vector<gsm::RawSegment> segments,
                                  v1::SegmentExtracted::Reason reason) {
  std::vector<RawSegmentJob> jobs;
  for (auto& segment : segments) {
    const size_t frame = size_t(std::max<int64_t>(segment.last_update_frame, 0));
    const uint64_t index =
        frame < session.frame_indices.size() ? session.frame_indices[frame] : session.last_index;
    jobs.push_back({std::move(segment), reason, index});
  }
  return jobs;
}

void ObjectDatabaseService::queueInserts(const std::shared_ptr<LiveSession>& session,
                                         const std::shared_ptr<IngestStream>& stream,
                                         std::vector<RawSegmentJob> jobs, bool may_wait) {
  for (auto& job : jobs) {
    auto shared = std::make_shared<RawSegmentJob>(std::move(job));
    auto work = [this, session, stream, shared] { (void)insert(*session, stream.get(), *shared); };
    if (may_wait) {
      database_queue_->pushWaiting(std::move(work));
    } else {
      database_queue_->push(std::move(work));
    }
  }
}

Status ObjectDatabaseService::insert(LiveSession& session, IngestStream* stream,
                                     RawSegmentJob& job) {
  const gsm::RawSegment& segment = job.segment;
  auto report = db_->insertSegment(session.name, segment);
  if (!report.ok()) {
    if (absl::IsFailedPrecondition(report.status()) || absl::IsInvalidArgument(report.status())) {
      // A segment the database cannot take (no surface at the mesh weight): skipped.
      logger("server")->debug("session {}: segment {} skipped: {}", session.name, segment.label,
                              std::string(report.status().message()));
      return absl::OkStatus();
    }
    const Status failed = annotate(
        report.status(), absl::StrFormat("inserting segment %d of session %s into the database",
                                         segment.label, session.name));
    logger("server")->error("{}", std::string(failed.message()));
    if (stream != nullptr) {
      std::lock_guard lock(stream->mutex);
      stream->cancelled = true;
      stream->changed.notify_all();
      stream->finish(toGrpcStatus(failed));
    }
    return failed;
  }
  candidates_skipped_.fetch_add(report->unreadable_candidates);
  const auto segment_id = store_->rawSegmentId({session.name, segment.label});
  {
    std::lock_guard lock(session.mutex);
    v1::SessionCounters& c = session.counters;
    c.set_segments_extracted(c.segments_extracted() + 1);
    // As the events say: a segment merged, or a model created for it.
    if (report->merged) {
      c.set_objects_merged(c.objects_merged() + 1);
    } else {
      c.set_objects_created(c.objects_created() + 1);
    }
  }
  if (stream == nullptr) return absl::OkStatus();
  v1::IngestResponse extracted;
  v1::SegmentExtracted& e = *extracted.mutable_segment();
  e.set_segment_id(segment_id.ok() ? uint64_t(*segment_id) : 0);
  e.set_gsm_label(segment.label);
  e.set_reason(job.reason);
  e.set_last_frame_index(job.last_frame_index);
  e.set_num_voxels(uint32_t(segment.label_voxels.size()));
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
  v1::IngestResponse event;
  v1::ObjectEvent& o = *event.mutable_object();
  o.set_segment_id(e.segment_id());
  stream->send(std::move(extracted));  // moves `e` away
  if (report->merged) {
    o.set_kind(v1::ObjectEvent::MERGED);
    o.set_into_object_id(uint64_t(report->model_id));
    for (const auto& r : report->results) {
      if (!r.accepted || r.model_id != report->model_id) continue;
      v1::MergeEvidence& ev = *o.mutable_evidence();
      ev.set_icp_rmse_m(r.registration.icp_rmse);
      ev.set_tsdf_rmse_m(r.model_verdict.agreement.rmse);
      ev.set_overlap_voxels(r.model_verdict.agreement.overlap);
      ev.set_non_overlap_voxels(r.model_verdict.agreement.compared -
                                r.model_verdict.agreement.overlap);
      *ev.mutable_t_into_merged() = toProto(r.registration.T_target_source);
      break;
    }
  } else {
    o.set_kind(v1::ObjectEvent::CREATED);
    o.set_object_id(uint64_t(report->model_id));
  }
  stream->send(std::move(event));
  return absl::OkStatus();
}

Status ObjectDatabaseService::flush(LiveSession& session) {
  if (!session.flush_extracted) {
    for (auto& job :
         jobsOf(session, session.map->extractIdle(true), v1::SegmentExtracted::SESSION_END)) {
      session.flush_jobs.push_back(std::move(job));
    }
    session.flush_extracted = true;
  }
  const size_t flushed = session.flush_jobs.size();
  while (!session.flush_jobs.empty()) {
    OBJDB_RETURN_IF_ERROR(insert(session, nullptr, session.flush_jobs.front()));
    session.flush_jobs.pop_front();
  }
  OBJDB_RETURN_IF_ERROR(store_->putScene(
      session.name, std::make_shared<const tsdf::TsdfLayer>(session.map->tsdf().clone()),
      std::make_shared<const gsm::LabelBlocks>(session.map->mainLabelBlocks())));
  const int64_t frames = int64_t(session.snapshot().frames_integrated());
  OBJDB_RETURN_IF_ERROR(store_->finishSession(session.name, storage::SessionState::kEnded, frames));
  {
    std::lock_guard lock(session.mutex);
    session.state = v1::SESSION_STATE_ENDED;
    session.ended_unix_s = nowUnixSeconds();
  }
  // The map is stored; free its memory.
  session.map.reset();
  session.segmenter.reset();
  logger("server")->info("session {} ended: {} frames, {} segments flushed at the end",
                         session.name, frames, flushed);
  return absl::OkStatus();
}

StatusOr<std::vector<uint64_t>> ObjectDatabaseService::objectsOf(const std::string& session) {
  std::vector<uint64_t> ids;
  storage::ModelQuery query;
  query.session = session;
  query.limit = kMaxPageSize;
  while (true) {
    OBJDB_ASSIGN_OR_RETURN(const std::vector<storage::ModelSummary> page,
                           store_->modelSummaries(query));
    for (const auto& m : page) ids.push_back(uint64_t(m.id));
    if (page.size() < query.limit) break;
    query.after_id = page.back().id;
  }
  return ids;
}

StatusOr<v1::SessionSummary> ObjectDatabaseService::summaryOf(LiveSession& session) {
  v1::SessionSummary summary;
  summary.set_session_name(session.name);
  {
    std::lock_guard lock(session.mutex);
    summary.set_state(session.state);
    *summary.mutable_counters() = session.counters;
  }
  OBJDB_ASSIGN_OR_RETURN(const std::vector<uint64_t> ids, objectsOf(session.name));
  for (uint64_t id : ids) summary.add_object_ids(id);
  return summary;
}

grpc::ServerBidiReactor<v1::IngestRequest, v1::IngestResponse>* ObjectDatabaseService::Ingest(
    grpc::CallbackServerContext* context) {
  if (const Status allowed = authorize(context, options_.token); !allowed.ok()) {
    return new RefusedCall<grpc::ServerBidiReactor<v1::IngestRequest, v1::IngestResponse>>(
        toGrpcStatus(allowed));
  }
  return new IngestReactor(this, context);
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
    auto stored = store_->sessions();
    if (!stored.ok()) return finishUnary(context, stored.status());
    for (const auto& s : *stored) {
      if (s.name != name) continue;
      if (s.state != storage::SessionState::kEnded) {
        auto saved_frames = store_->savedMapFrames(name);
        if (!saved_frames.ok()) return finishUnary(context, saved_frames.status());
        if (*saved_frames >= 0) {
          return finishUnary(context, recoveryFailed(name, *saved_frames));
        }
        auto scene = store_->scene(name);
        if (!scene.ok()) return finishUnary(context, scene.status());
        if (*scene != nullptr) {
          return finishUnary(context, absl::FailedPreconditionError(absl::StrFormat(
                                          "session %s was not ended before the server stopped; "
                                          "it was ended at the next start from its map saved "
                                          "after %d frames (its segments are in the database, "
                                          "its scene is stored); the frames after it were lost",
                                          name, s.frames)));
        }
        return finishUnary(context, absl::FailedPreconditionError(absl::StrFormat(
                                        "session %s was not ended before the server stopped; "
                                        "its map was not kept (the segments inserted before are "
                                        "in the database), so it cannot be flushed any more",
                                        name)));
      }
      v1::SessionSummary& summary = *response->mutable_summary();
      summary.set_session_name(name);
      summary.set_state(v1::SESSION_STATE_ENDED);
      summary.mutable_counters()->set_frames_integrated(uint64_t(s.frames));
      auto ids = objectsOf(name);
      if (!ids.ok()) return finishUnary(context, ids.status());
      for (uint64_t id : *ids) summary.add_object_ids(id);
      return finishUnary(context, absl::OkStatus());
    }
    return finishUnary(context,
                       absl::NotFoundError(absl::StrFormat("no session named \"%s\"", name)));
  }
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  // On the database thread, after every segment queued before it: flush once, then answer. A
  // second call queued behind the flush answers with the ended session's summary.
  auto job = [this, session, reactor, response] {
    Status status = absl::OkStatus();
    if (!session->ended()) status = flush(*session);
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
      session->after_stream.push_back(std::move(job));
      return reactor;
    }
  }
  database_queue_->push(std::move(job));
  return reactor;
}

void ObjectDatabaseService::describe(const storage::SessionInfo& stored, v1::SessionInfo* out) {
  out->set_session_name(stored.name);
  out->set_state(toProto(stored.state));
  out->set_started_unix_s(unixSeconds(stored.started_at));
  out->set_ended_unix_s(unixSeconds(stored.ended_at));
  *out->mutable_intrinsics() = intrinsicsFromJson(stored.intrinsics_json);
  out->mutable_counters()->set_frames_integrated(uint64_t(stored.frames));
  // A session this server runs: its live state and counters.
  if (std::shared_ptr<LiveSession> live = liveSession(stored.name)) {
    std::lock_guard lock(live->mutex);
    out->set_state(live->state);
    out->set_client_info(live->client_info);
    out->set_started_unix_s(live->started_unix_s);
    out->set_ended_unix_s(live->ended_unix_s);
    *out->mutable_counters() = live->counters;
  }
}

grpc::ServerUnaryReactor* ObjectDatabaseService::ListSessions(
    grpc::CallbackServerContext* context, const v1::ListSessionsRequest* request,
    v1::ListSessionsResponse* response) {
  if (const Status allowed = authorize(context, options_.token); !allowed.ok()) {
    return finishUnary(context, allowed);
  }
  auto after = parsePageToken(request->page_token(), 's', 0);
  if (!after.ok()) return finishUnary(context, after.status());
  auto stored = store_->sessions();
  if (!stored.ok()) return finishUnary(context, stored.status());
  const uint32_t limit = pageSize(request->page_size());
  int64_t last = *after;
  for (const auto& s : *stored) {
    if (s.id <= *after) continue;
    if (response->sessions_size() == int(limit)) {
      response->set_next_page_token(pageToken('s', last, 0));
      break;
    }
    describe(s, response->add_sessions());
    last = s.id;
  }
  return finishUnary(context, absl::OkStatus());
}

grpc::ServerUnaryReactor* ObjectDatabaseService::ListObjects(grpc::CallbackServerContext* context,
                                                             const v1::ListObjectsRequest* request,
                                                             v1::ListObjectsResponse* response) {
  if (const Status allowed = authorize(context, options_.token); !allowed.ok()) {
    return finishUnary(context, allowed);
  }
  const uint64_t filter = std::hash<std::string>()(request->session_name()) * 2 +
                          (request->include_merged() ? 1 : 0);
  auto after = parsePageToken(request->page_token(), 'o', filter);
  if (!after.ok()) return finishUnary(context, after.status());
  if (!request->session_name().empty()) {
    auto stored = store_->sessions();
    if (!stored.ok()) return finishUnary(context, stored.status());
    const bool known = std::any_of(stored->begin(), stored->end(), [&](const auto& s) {
      return s.name == request->session_name();
    });
    if (!known) {
      return finishUnary(context, absl::NotFoundError(absl::StrFormat(
                                      "no session named \"%s\"", request->session_name())));
    }
  }
  storage::ModelQuery query;
  query.after_id = *after;
  query.limit = pageSize(request->page_size()) + 1;  // one more: is there a next page?
  query.session = request->session_name();
  query.include_merged = request->include_merged();
  auto models = store_->modelSummaries(query);
  if (!models.ok()) return finishUnary(context, models.status());
  const bool more = models->size() == query.limit;
  if (more) models->pop_back();
  for (const auto& m : *models) toProto(m, response->add_objects());
  if (more) response->set_next_page_token(pageToken('o', models->back().id, filter));
  return finishUnary(context, absl::OkStatus());
}

grpc::ServerUnaryReactor* ObjectDatabaseService::GetObject(grpc::CallbackServerContext* context,
                                                           const v1::GetObjectRequest* request,
                                                           v1::ObjectDetail* response) {
  if (const Status allowed = authorize(context, options_.token); !allowed.ok()) {
    return finishUnary(context, allowed);
  }
  auto run = [&]() -> Status {
    if (request->id() == 0 || request->id() > uint64_t(INT64_MAX)) {
      return absl::NotFoundError(absl::StrFormat("no object %d", request->id()));
    }
    const int64_t id = int64_t(request->id());
    storage::ModelQuery query;
    query.after_id = id - 1;
    query.limit = 1;
    query.include_merged = true;
    OBJDB_ASSIGN_OR_RETURN(const std::vector<storage::ModelSummary> found,
                           store_->modelSummaries(query));
    if (found.empty() || found.front().id != id) {
      return absl::NotFoundError(absl::StrFormat("no object %d", request->id()));
    }
    const storage::ModelSummary& summary = found.front();
    toProto(summary, response->mutable_summary());
    v1::ObjectStats& stats = *response->mutable_stats();
    std::set<uint64_t> segments;
    for (const auto& o : summary.observations) {
      v1::ObjectPose& pose = *response->add_poses();
      pose.set_session_name(o.session);
      *pose.mutable_t_world_object() = toProto(o.T_world_object);
      pose.set_segment_id(uint64_t(o.raw_segment_id));
      if (o.raw_segment_id > 0) segments.insert(uint64_t(o.raw_segment_id));
    }
    for (uint64_t s : segments) stats.add_segment_ids(s);
    stats.set_num_points(uint32_t(summary.num_points));
    stats.set_num_keypoints(uint32_t(summary.num_keypoints));
    stats.set_voxel_size_m(summary.voxel_size);
    stats.set_num_merges(uint32_t(summary.merges));
    if (summary.state != "active") return absl::OkStatus();  // merged: its geometry moved on
    OBJDB_ASSIGN_OR_RETURN(const std::shared_ptr<const model::ObjectModel> model, store_->model(id));
    const size_t per_block = size_t(std::pow(model->grid.voxelsPerSide(), 3));
    stats.set_num_voxels(uint32_t(model->grid.numBlocks() * per_block));
    if (request->include_mesh()) {
      toProto(tsdf::extractMesh(model->grid, options_.params.tsdf.mesh_min_weight),
              response->mutable_mesh());
    }
    if (request->include_cloud()) toProto(model->cloud, response->mutable_cloud());
    const size_t bytes = response->ByteSizeLong();
    if (bytes > options_.max_send_message_bytes) {
      return absl::ResourceExhaustedError(absl::StrFormat(
          "object %d with its %s is %d bytes, above the server's message limit of %d bytes; ask "
          "for less (include_mesh / include_cloud)",
          id, request->include_mesh() ? "mesh" : "cloud", bytes, options_.max_send_message_bytes));
    }
    return absl::OkStatus();
  };
  const Status status = run();
  if (!status.ok()) response->Clear();
  return finishUnary(context, status);
}

// Streams a session's mesh in chunks; the mesh is made on a worker thread.
class SceneMeshReactor final : public grpc::ServerWriteReactor<v1::MeshChunk> {
 public:
  void start(std::vector<TriangleMesh> chunks) {
    std::lock_guard lock(mutex_);
    chunks_ = std::move(chunks);
    writeNext();
  }
  void fail(const Status& status) {
    std::lock_guard lock(mutex_);
    Finish(toGrpcStatus(status));
  }
  void OnWriteDone(bool ok) override {
    std::lock_guard lock(mutex_);
    if (!ok) {
      Finish(grpc::Status(grpc::StatusCode::CANCELLED, "the client stopped reading"));
      return;
    }
    writeNext();
  }
  // start() and fail() run on a worker thread and may call Finish, after which gRPC may call
  // OnDone on another thread before they have released the mutex: wait for it before deleting.
  void OnDone() override {
    { std::lock_guard lock(mutex_); }
    delete this;
  }

 private:
  void writeNext() {
    if (next_ >= chunks_.size()) {
      Finish(grpc::Status::OK);
      return;
    }
    chunk_.Clear();
    chunk_.set_chunk_index(uint32_t(next_));
    chunk_.set_last(next_ + 1 == chunks_.size());
    toProto(chunks_[next_], chunk_.mutable_mesh());
    chunks_[next_] = TriangleMesh();
    ++next_;
    StartWrite(&chunk_);
  }
  std::mutex mutex_;
  std::vector<TriangleMesh> chunks_;
  size_t next_ = 0;
  v1::MeshChunk chunk_;
};

grpc::ServerWriteReactor<v1::MeshChunk>* ObjectDatabaseService::GetSceneMesh(
    grpc::CallbackServerContext* context, const v1::GetSceneMeshRequest* request) {
  if (const Status allowed = authorize(context, options_.token); !allowed.ok()) {
    return new RefusedCall<grpc::ServerWriteReactor<v1::MeshChunk>>(toGrpcStatus(allowed));
  }
  auto* reactor = new SceneMeshReactor();
  const std::string name = request->session_name();
  const bool completed = request->completed();
  startWorker([this, reactor, name, completed, context] {
    auto run = [&]() -> StatusOr<std::vector<TriangleMesh>> {
      OBJDB_RETURN_IF_ERROR(checkNotRecovering(name));
      OBJDB_ASSIGN_OR_RETURN(const std::vector<storage::SessionInfo> stored, store_->sessions());
      const auto it = std::find_if(stored.begin(), stored.end(),
                                   [&](const auto& s) { return s.name == name; });
      if (it == stored.end()) {
        return absl::NotFoundError(absl::StrFormat("no session named \"%s\"", name));
      }
      OBJDB_ASSIGN_OR_RETURN(const std::shared_ptr<const tsdf::TsdfLayer> scene,
                             store_->scene(name));
      if (!scene) {
        if (it->state == storage::SessionState::kOpen || liveSession(name) != nullptr) {
          return absl::FailedPreconditionError(absl::StrFormat(
              "session %s has no stored map yet (state %s): EndSession stores it", name,
              storage::sessionStateName(it->state)));
        }
        OBJDB_ASSIGN_OR_RETURN(const int64_t saved_frames, store_->savedMapFrames(name));
        if (saved_frames >= 0) {
          return recoveryFailed(name, saved_frames);
        }
        return absl::FailedPreconditionError(absl::StrFormat(
            "session %s has no stored map (state %s): it was not ended before the server stopped "
            "and its map was not kept",
            name, storage::sessionStateName(it->state)));
      }
      // The session's own parameters decide its mesh; the server's its completion.
      const Params params = storedSessionParams(*it);
      TriangleMesh mesh;
      if (completed) {
        // A deadline or a cancel stops the work between models.
        OBJDB_ASSIGN_OR_RETURN(
            const tsdf::TsdfLayer full,
            completion::completeScene(*store_, name, options_.params.merging,
                                      params.tsdf.max_weight, nullptr,
                                      [context] { return context->IsCancelled(); }));
        mesh = tsdf::extractMesh(full, params.tsdf.mesh_min_weight);
      } else {
        mesh = tsdf::extractMesh(*scene, params.tsdf.mesh_min_weight);
      }
      return splitMesh(mesh, options_.mesh_chunk_bytes);
    };
    auto chunks = run();
    if (!chunks.ok()) {
      if (absl::IsCancelled(chunks.status())) jobs_cancelled_.fetch_add(1);
      reactor->fail(chunks.status());
      return;
    }
    if (chunks->empty()) chunks->emplace_back();  // one (empty, last) chunk: the mesh is empty
    reactor->start(*std::move(chunks));
  });
  return reactor;
}

grpc::ServerUnaryReactor* ObjectDatabaseService::GetStats(grpc::CallbackServerContext* context,
                                                          const v1::GetStatsRequest*,
                                                          v1::GetStatsResponse* response) {
  if (const Status allowed = authorize(context, options_.token); !allowed.ok()) {
    return finishUnary(context, allowed);
  }
  auto run = [&]() -> Status {
    OBJDB_ASSIGN_OR_RETURN(const std::vector<storage::SessionInfo> stored, store_->sessions());
    OBJDB_ASSIGN_OR_RETURN(const storage::StoreStats stats, store_->stats());
    response->set_server_version(options_.version);
    response->set_uptime_s(
        std::chrono::duration<double>(std::chrono::steady_clock::now() - started_).count());
    response->set_sessions_total(stored.size());
    uint64_t frames = 0;
    uint32_t open = 0;
    for (const auto& s : stored) {
      std::shared_ptr<LiveSession> live = liveSession(s.name);
      if (!live) {
        frames += uint64_t(s.frames);
        continue;
      }
      std::lock_guard lock(live->mutex);
      frames += live->counters.frames_integrated();
      open += live->streaming ? 1 : 0;
    }
    response->set_sessions_open(open);
    response->set_frames_integrated(frames);
    response->set_objects_active(uint64_t(stats.active_models));
    response->set_objects_merged(uint64_t(stats.merged_models));
    for (const auto& t : stats.tables) {
      if (t.table == "raw_segments") response->set_segments_total(uint64_t(t.rows));
    }
    response->set_database_size_bytes(uint64_t(fileBytes(store_->path())));
    response->set_queued_segments(uint32_t(database_queue_->pending()));
    response->set_jobs_cancelled(jobs_cancelled_.load());
    response->set_candidates_skipped(candidates_skipped_.load());
    return absl::OkStatus();
  };
  return finishUnary(context, run());
}

}  // namespace objdb::server
