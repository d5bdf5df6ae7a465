// objdb.v1.ObjectDatabase (docs/architecture.md: data flow, threads): the server's sessions and the
// queries over its database. The frame pipeline itself is server/session/live_session.h, the
// Ingest call's reactor server/ingest_stream.h; this class owns the sessions, the database thread
// and the RPC handlers (queries in queries.cpp, a stream's pipeline in session_stream.cpp,
// recovery, takeover and leases in session_recovery.cpp).
//
// - Ingest: one stream = one session. The header is checked (name, intrinsics, parameters; the
//   database's model settings must stay the same) and the session stored as open; per stream, a
//   segmentation thread decodes and segments each frame, one frame ahead of the frame worker,
//   which validates it, fuses it into the session's Global Segmentation Map and acks it; idle
//   segments go to the database queue (extraction is put off while the queue is full, so the
//   database never stalls the frames). At most
//   `frame_queue` frames wait per stream: beyond that the server stops reading (the client's
//   writes block) — backpressure.
// - One database thread runs Algorithm 1 for every extracted segment, in extraction order, and
//   sends the SegmentExtracted and ObjectEvent messages back on the stream.
// - EndSession flushes the map (every live label), inserts the rest, stores the scene map and
//   ends the session, on the database thread.
// - The queries read the store (storage/store.h) on a bounded pool of their own
//   (server/query_pool.h), GetSceneMesh on another: gRPC's callback threads only take and answer
//   calls, and a full pool refuses at once (RESOURCE_EXHAUSTED).
// - A session's map lives in memory from its header to EndSession. A server that stops ends
//   every session not ended yet and stores its map; only a crash loses the frames after the
//   session's last saved map (--save-map-s), and the next start ends it from that map
//   (INTERRUPTED). A resume of such a session streams it again from its first frame
//   (resumeSession).
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <list>
#include <map>
#include <memory>
#include <optional>
#include <mutex>
#include <set>
#include <string>
#include <thread>

#include "core/common/params.h"
#include "core/common/status.h"
#include "core/database/object_database.h"
#include "objdb/v1/objdb.grpc.pb.h"
#include "server/query_pool.h"
#include "server/session/published_scenes.h"
#include "storage/store.h"

namespace objdb::database {
class ObjectDatabase;
}

namespace objdb::server {

class JobQueue;
struct LiveSession;
struct IngestStream;
struct RawSegmentJob;
struct MapCopy;
struct PreparedFrame;

struct ServiceOptions {
  Params params;                    // the server's parameters; sessions may override some
  size_t frame_queue = 8;           // frames buffered per stream before reading pauses
  size_t max_open_sessions = 16;    // sessions with a map in memory; more: RESOURCE_EXHAUSTED
  size_t ended_sessions_kept = 64;  // ServerOptions::ended_sessions_kept
  // A session whose stream closed or broke and that gets no EndSession for this long is ended by
  // the server (map stored, segments inserted). 0 = never.
  std::chrono::milliseconds auto_end_after{10 * 60 * 1000};
  // An open session's map (TSDF + main labels) is saved this often, so that a crash loses only
  // the frames after the last save: the next start ends the session from it. 0 = never.
  std::chrono::milliseconds save_map_every{60 * 1000};
  // Events (acks, segment and object events) waiting for a client that does not read its Ingest
  // stream: at this many its frame worker stops taking frames (so the client's writes block); if
  // the client then reads none of them for slow_reader_timeout, the stream ends with
  // RESOURCE_EXHAUSTED and the session is kept (INTERRUPTED), as after a broken stream.
  size_t max_pending_events = 64;
  std::chrono::milliseconds slow_reader_timeout{60 * 1000};
  size_t segment_queue = 64;        // segments waiting for the database before extraction is put off
  int integration_threads = 2;      // TSDF integration threads per session
  size_t mesh_chunk_bytes = 1 << 20;           // GetSceneMesh chunk size
  size_t max_send_message_bytes = 16 << 20;    // GetObject larger than this: RESOURCE_EXHAUSTED
  std::string version = "0.1.0";
  // Several servers on one database (docs/storage.md): each session is leased by the server that
  // streams or ends it, renewed every lease_ttl / 3; a lease not renewed for lease_ttl expires,
  // and then another server takes the session over (ends it from its saved map, as at a
  // restart). `server_id` names this server as lease holder; empty: host:pid:random.
  std::string server_id;
  std::chrono::milliseconds lease_ttl{15 * 1000};
  // Every call must carry "authorization: Bearer <token>" (server/auth.h); empty = no token.
  std::string token;
  // The unary queries' pool (ListSessions, ListObjects, GetObject, GetStats, EndSession of a
  // session not in memory) and GetSceneMesh's: threads, and calls that may wait for one; more
  // are refused with RESOURCE_EXHAUSTED.
  int query_threads = 4;
  size_t query_queue = 256;
  int scene_threads = 2;
  size_t scene_queue = 16;
};

class ObjectDatabaseService final : public v1::ObjectDatabase::CallbackService {
 public:
  // Loads the database's prefilter entries (the store outlives the service). Errors: the
  // parameters, or a store that cannot be read.
  static StatusOr<std::unique_ptr<ObjectDatabaseService>> create(const ServiceOptions& options,
                                                                 storage::Store* store);
  ~ObjectDatabaseService() override;  // stop()

  // The sessions a stopped server left not ended (found by create()): open ones are marked
  // INTERRUPTED, and those with a saved map are ended from it on the database thread; a session
  // another live server holds the lease of is its own and left alone. Call once the server
  // listens: create() itself writes nothing, so a server that cannot start changes nothing.
  // Errors: the store's; at the first, nothing more is marked or queued. From then on the lease
  // keeper takes over, the same way, every open session whose server stopped renewing its lease.
  Status startRecovery();
  // This server's name as lease holder (ServiceOptions::server_id, or the one made up).
  const std::string& serverId() const { return server_id_; }

  // The drain began (before the gRPC server's Shutdown): queries that come now are answered
  // UNAVAILABLE "the server is shutting down" instead of being started.
  void beginDrain() { draining_.store(true); }
  // After the gRPC server stopped (no call in flight): waits for the workers, then ends every
  // session that did not end (its map is stored; if that fails it is stored as interrupted) and
  // runs the database queue dry. Later calls return at once.
  void stop();

  // The calls of objdb.v1.ObjectDatabase.
  using Context = grpc::CallbackServerContext;
  grpc::ServerBidiReactor<v1::IngestRequest, v1::IngestResponse>* Ingest(Context* context) override;
  grpc::ServerUnaryReactor* EndSession(Context* context, const v1::EndSessionRequest* request,
                                       v1::EndSessionResponse* response) override;
  grpc::ServerUnaryReactor* ListSessions(Context* context, const v1::ListSessionsRequest* request,
                                         v1::ListSessionsResponse* response) override;
  grpc::ServerUnaryReactor* ListObjects(Context* context, const v1::ListObjectsRequest* request,
                                        v1::ListObjectsResponse* response) override;
  grpc::ServerUnaryReactor* GetObject(Context* context, const v1::GetObjectRequest* request,
                                      v1::ObjectDetail* response) override;
  grpc::ServerWriteReactor<v1::MeshChunk>* GetSceneMesh(
      Context* context, const v1::GetSceneMeshRequest* request) override;
  grpc::ServerUnaryReactor* GetStats(Context* context, const v1::GetStatsRequest* request,
                                     v1::GetStatsResponse* response) override;
  // On the query pool (match_query.cpp), beside the database thread's inserts.
  grpc::ServerUnaryReactor* Match(Context* context, const v1::MatchRequest* request,
                                  v1::MatchResponse* response) override;
  // "What is here?" (region_queries.cpp), on the query pool.
  grpc::ServerUnaryReactor* ObjectsInRegion(Context* context,
                                            const v1::ObjectsInRegionRequest* request,
                                            v1::ObjectsInRegionResponse* response) override;
  grpc::ServerUnaryReactor* SessionChanges(Context* context,
                                           const v1::SessionChangesRequest* request,
                                           v1::SessionChangesResponse* response) override;

 private:
  friend class SceneMeshReactor;
  ObjectDatabaseService(const ServiceOptions& options, storage::Store* store,
                        std::unique_ptr<database::ObjectDatabase> db);

  // Ingest (session_open.cpp).
  // The session of a stream's header, as its if_exists says: a new one (beginNewSession), an
  // existing one continued (resumeSession) or replaced (replaceSession, then a new one); fills
  // `opened`, the stream's first response.
  StatusOr<std::shared_ptr<LiveSession>> openSession(const v1::SessionHeader& header,
                                                     const std::shared_ptr<IngestStream>& stream,
                                                     v1::SessionOpened* opened);
  // Checks the header, builds the session's segmenter and map, stores the session as open and
  // publishes it (with its stream). Errors: the header's, ALREADY_EXISTS (saying what the client
  // can do), RESOURCE_EXHAUSTED.
  StatusOr<std::shared_ptr<LiveSession>> beginNewSession(
      const v1::SessionHeader& header, const std::shared_ptr<IngestStream>& stream);
  // The live session of the header's name, attached to `stream` when this server holds its map
  // and nothing feeds it. Null: no session of that name (open a new one), or, with
  // `*from_first_frame`, an interrupted session whose map this server does not hold (its server
  // crashed since): it is replaced and streamed again from its first frame. Errors:
  // FAILED_PRECONDITION (ended, still streaming, being ended), UNAVAILABLE (being ended from its
  // saved map at this start), INVALID_ARGUMENT (intrinsics or parameters differ from the
  // session's).
  StatusOr<std::shared_ptr<LiveSession>> resumeSession(const v1::SessionHeader& header,
                                                       const std::shared_ptr<IngestStream>& stream,
                                                       bool* from_first_frame);
  // Withdraws every segment session `name` inserted (on the database thread), forgets its live
  // map, and frees its name (Store::retireSession). Returns the segments withdrawn, or nothing
  // when no session has that name. FAILED_PRECONDITION while a stream feeds it, its end runs, or
  // another server holds it.
  StatusOr<std::optional<uint64_t>> replaceSession(const std::string& name);
  // A session whose stream ended before any frame came (frame worker): not kept; its row is
  // deleted on the database thread (retireEmptySession, which flush() calls too).
  void forgetEmptySession(const std::shared_ptr<LiveSession>& session);
  void retireEmptySession(LiveSession& session);
  // RESOURCE_EXHAUSTED when max_open_sessions sessions are not ended (mutex_ held).
  Status checkSessionLimit();
  // Ended sessions stay in memory, counters and all, for a repeated EndSession and for
  // ListSessions; beyond the options_.ended_sessions_kept most recently ended, the oldest are
  // dropped (the store answers for them, with the counters it keeps: frames and objects).
  void forgetEndedSessions();
  void startWorker(std::function<void()> work);
  // Runs `work` (which fills the call's response) on the query pool and finishes the call with
  // its status; a full or stopped pool answers at once.
  grpc::ServerUnaryReactor* answerOffThread(grpc::CallbackServerContext* context,
                                            std::function<Status()> work);
  // answerOffThread for a call that authorize() lets in (others are answered at once).
  grpc::ServerUnaryReactor* answerAuthorized(grpc::CallbackServerContext* context,
                                             std::function<Status()> work);
  void runStream(std::shared_ptr<IngestStream> stream);
  // The frame worker is done with the session's map: hands EndSession jobs that waited for it to
  // the database queue; an interrupted session is stored as such (on the database thread).
  void endStreaming(const std::shared_ptr<LiveSession>& session, bool interrupted);
  // Fuses one segmented frame (integrateFrame), acks it, extracts idle segments for the
  // database and saves the map when due (the frame worker's thread).
  void processFrame(const std::shared_ptr<IngestStream>& stream, const v1::Frame& frame,
                    const PreparedFrame& prepared);
  // Every save_map_every (frame worker): a copy of the map to the database thread, which saves
  // it; skipped while the previous save is still waiting.
  void maybeSaveMap(const std::shared_ptr<LiveSession>& session);
  // Database thread: a session whose stream is gone, saved once more if frames came after its
  // last save (queued by the janitor).
  void saveIdleMap(const std::shared_ptr<LiveSession>& session);
  // Database thread: stores one save (skipped when the session has ended meanwhile): the blocks
  // changed since the last (writeSavedMapOf); counted as published while publish_maps_.
  void storeSavedMap(LiveSession& session, const MapCopy& copy);
  // Several servers on one database (the lease keeper's thread): live maps are published while
  // another server holds a lease (server/session/published_scenes.h). When one comes, every
  // live session's map is saved at once (by its frame worker, or by the janitor when its stream
  // is gone), since the maps of its extractions so far were not published.
  void updatePublication();
  // Database thread, at start: a session a stopped server left not ended, with a saved map, gets
  // that map's segments inserted and its scene stored, and stays INTERRUPTED.
  Status recoverSession(const storage::SessionInfo& stored);
  // Sessions of a stopped server (this one before a restart, or another whose lease expired):
  // each that needs ending (open, or with a saved map) is leased, marked INTERRUPTED when open,
  // and ended from its saved map on the database thread; the lease goes when that is done. A
  // session whose lease another server holds is skipped. `at_start`: the sessions were
  // announced as recovering by create().
  Status takeOver(const std::vector<storage::SessionInfo>& unended, bool at_start);
  // The lease keeper's thread: renews this server's leases every lease_ttl / 3, stops the
  // sessions whose lease it lost, and takes over open sessions whose lease expired.
  void keepLeases();
  // Sessions whose lease this server holds no more (expired while the database was unreachable,
  // taken by another server): their streams end and nothing more of them is written.
  void leasesLost(const std::vector<std::string>& lost);
  // Gives up the lease of `name` (its session ended, or its recovery is done).
  void releaseLease(const std::string& name);
  // The lease of a session about to be created. ALREADY_EXISTS when this server streams it
  // already or another server holds its lease.
  Status leaseNewSession(const std::string& name);
  // The stored row of session `name` (NOT_FOUND when none).
  StatusOr<storage::SessionInfo> sessionNamed(const std::string& name);
  // ABORTED: the session's lease was lost.
  static Status lostLease(const std::string& name);
  // The server's parameters with a stored session's own on top (the server's alone when they
  // cannot be applied).
  Params storedSessionParams(const storage::SessionInfo& stored) const;
  // FAILED_PRECONDITION: ending the session from its map saved after `saved_frames` frames
  // failed at this start (the saved map is still there).
  static Status recoveryFailed(const std::string& name, int64_t saved_frames);
  // UNAVAILABLE while the session `name` is being ended from its saved map.
  Status checkNotRecovering(const std::string& name);
  // Queues the database insert of each segment, never waiting (frame workers insert what they
  // extracted even when their stream was cancelled: nothing extracted is lost).
  void queueInserts(const std::shared_ptr<LiveSession>& session,
                    const std::shared_ptr<IngestStream>& stream, std::vector<RawSegmentJob> jobs);
  // Algorithm 1 for one segment (database thread); events go to `stream` when given. Errors:
  // storage failures (a segment the database cannot take is skipped, OK).
  Status insert(LiveSession& session, IngestStream* stream, RawSegmentJob& job);
  // A segment the GSM withdrew, given back by the database (counted in segments_withdrawn).
  // The id of a stored raw segment (0 when the store has none or cannot say).
  uint64_t segmentIdOf(const std::string& session, gsm::Label label) const;
  // Sends each event on the session's stream, in order.
  static void sendObjectEvents(IngestStream* stream, std::vector<v1::ObjectEvent> events);
  Status withdraw(LiveSession& session, IngestStream* stream, gsm::Label label);
  // Runs on the database thread: extract everything, insert, store the scene, end the session.
  Status flush(LiveSession& session);
  // flush() unless the session ended already; failures are logged (database thread).
  Status endByServer(LiveSession& session);
  // The janitor thread: ends sessions left without EndSession for auto_end_after.
  void endIdleSessions();
  StatusOr<v1::SessionSummary> summaryOf(LiveSession& session);
  StatusOr<std::vector<uint64_t>> objectsOf(const std::string& session);
  void describe(const storage::SessionInfo& stored, v1::SessionInfo* out);
  std::shared_ptr<LiveSession> liveSession(const std::string& name);

  const ServiceOptions options_;
  storage::Store* store_;
  // Inserts and withdrawals on the database thread only; Match reads it on the query pool
  // (ObjectDatabase::match is safe beside inserts).
  std::unique_ptr<database::ObjectDatabase> db_;
  PublishedScenes published_scenes_{store_};  // live maps across servers
  // Another server holds a session lease on this (shared) database: extractions publish their
  // maps (LiveSession::publish_scenes points here).
  std::atomic<bool> publish_maps_{false};
  const std::chrono::steady_clock::time_point started_ = std::chrono::steady_clock::now();

  std::mutex mutex_;  // guards sessions_, recovering_, workers_, stopped_
  std::map<std::string, std::shared_ptr<LiveSession>> sessions_;
  std::set<std::string> recovering_;  // sessions whose saved maps are still being ended
  std::vector<storage::SessionInfo> unended_;  // from create() to startRecovery()
  struct Worker {
    std::thread thread;
    std::shared_ptr<std::atomic<bool>> finished;
  };
  std::list<Worker> workers_;
  bool stopped_ = false;
  size_t opening_ = 0;  // sessions between their limit check and their publication
  std::atomic<bool> draining_{false};

  std::atomic<uint64_t> jobs_cancelled_{0};
  std::atomic<uint64_t> candidates_skipped_{0};
  // Model-to-scene verification since start (GetStats): poses verified, candidates rejected at
  // the scene check, and poses that had no scene map (each rejects its candidate).
  std::atomic<uint64_t> scene_checks_{0};
  std::atomic<uint64_t> candidates_rejected_by_scene_{0};
  std::atomic<uint64_t> poses_without_scene_{0};
  std::atomic<uint64_t> merges_same_place_{0};
  std::atomic<uint64_t> extractions_deferred_{0};
  // Segments stored without a model (InsertReport::unusable), and inserts that failed.
  std::atomic<uint64_t> segments_unusable_{0};
  std::atomic<uint64_t> insert_errors_{0};
  // Insert time by stage since start (GetStats insert_timings).
  std::mutex timings_mutex_;
  database::InsertTimings insert_timings_;
  uint64_t inserts_ = 0;
  std::condition_variable janitor_wake_;  // with mutex_: stop() wakes the janitor
  std::thread janitor_;
  // Leases (session_recovery.cpp). leased_ (under mutex_): the sessions whose lease this server
  // holds; the keeper thread renews them.
  std::string server_id_;
  std::set<std::string> leased_;
  bool recovery_started_ = false;  // startRecovery ran: the keeper may take sessions over
  bool keeper_stop_ = false;       // stop() ended every session: the keeper's work is done
  std::condition_variable keeper_wake_;  // with mutex_: stop() wakes the keeper
  std::thread keeper_;
  std::atomic<uint64_t> sessions_taken_over_{0};
  std::atomic<uint64_t> leases_lost_{0};
  std::atomic<uint64_t> queries_refused_{0};  // a pool was full
  std::unique_ptr<QueryPool> queries_, scenes_;  // stopped by stop(), after the streams
  std::unique_ptr<JobQueue> database_queue_;  // last: its thread stops first
};

}  // namespace objdb::server
