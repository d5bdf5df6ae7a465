// The read-only calls of the ObjectDatabase service: ListSessions, ListObjects, GetObject,
// GetSceneMesh (meshed on a worker thread, streamed in chunks) and GetStats. They read the store
// (storage/store.h); a live session adds its in-memory state and counters.
#include <algorithm>
#include <cmath>
#include <set>
#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "core/completion/scene_completion.h"
#include "core/database/merge_source.h"
#include "core/tsdf/mesh_extraction.h"
#include "server/job_queue.h"
#include "server/object_database_service.h"
#include "server/proto_convert.h"
#include "server/service_util.h"
#include "server/session/live_session.h"

namespace objdb::server {
namespace {

// InsertTimingTotals.<stage>_s of each stage of database::kInsertStages (null: the API has
// no such field; proto_convert_test checks that every stage has one).
const google::protobuf::FieldDescriptor* totalsFieldOf(const char* stage) {
  return v1::InsertTimingTotals::descriptor()->FindFieldByName(absl::StrCat(stage, "_s"));
}

// NOT_FOUND for an id that is no object now, saying what became of it: a removed model's
// segment went to its successor, which may have merged on since (the chain is followed).
Status noObject(const storage::Store& store, int64_t id) {
  OBJDB_ASSIGN_OR_RETURN(const storage::ModelFate fate, store.modelFate(id));
  if (fate.state != "removed") return absl::NotFoundError(absl::StrFormat("no object %d", id));
  int64_t next = fate.next;
  for (int hop = 0; next > 0 && hop < 1000; ++hop) {
    OBJDB_ASSIGN_OR_RETURN(const storage::ModelFate now, store.modelFate(next));
    if (now.state == "active") {
      return absl::NotFoundError(absl::StrFormat(
          "object %d was removed; its segment is in object %d now", id, next));
    }
    next = now.next;
  }
  return absl::NotFoundError(absl::StrFormat(
      "object %d was removed; no object holds its segment now (it was withdrawn: its GSM label "
      "joined another, whose segment carries its surface; or it holds no surface any more)",
      id));
}

// The parts of `summary` at each of its poses, from the raw segments' voxels (in pose order, then
// by label); with `voxels`, each part's voxel centres too. A pose whose segment row is gone, or
// that was stored before parts had geometry, gives none.
Status addParts(const storage::Store& store, const storage::ModelSummary& summary,
                bool voxels, google::protobuf::RepeatedPtrField<v1::ObjectPart>* out) {
  for (const auto& o : summary.observations) {
    if (o.raw_segment_id <= 0) continue;
    OBJDB_ASSIGN_OR_RETURN(const auto segment, store.rawSegment({o.session, o.label}));
    if (segment->voxel_parts.empty()) continue;
    const Eigen::Isometry3d T_object_segment = o.T_world_object.inverse() * segment->T_world_segment;
    std::map<uint32_t, v1::ObjectPart*> part_of;
    for (const uint32_t label : o.parts) {
      v1::ObjectPart* part = out->Add();
      part->set_session_name(o.session);
      part->set_segment_id(uint64_t(o.raw_segment_id));
      part->set_label(label);
      part_of[label] = part;
    }
    std::map<uint32_t, std::pair<Eigen::Vector3d, Eigen::Vector3d>> bounds;
    for (size_t i = 0; i < segment->voxels.size(); ++i) {
      auto it = part_of.find(segment->voxel_parts[i]);
      if (it == part_of.end()) {
        return absl::DataLossError(absl::StrFormat(
            "raw segment %s/%d: a voxel of part %d, which is not one of its parts", o.session,
            o.label, segment->voxel_parts[i]));
      }
      v1::ObjectPart& part = *it->second;
      const Eigen::Vector3d p =
          T_object_segment * segment->grid->voxelCenter(segment->voxels[i]).cast<double>();
      part.set_num_voxels(part.num_voxels() + 1);
      auto [b, fresh] = bounds.try_emplace(part.label(), p, p);
      if (!fresh) {
        b->second.first = b->second.first.cwiseMin(p);
        b->second.second = b->second.second.cwiseMax(p);
      }
      if (voxels) {
        for (int k = 0; k < 3; ++k) part.mutable_voxels()->add_points(float(p[k]));
      }
    }
    for (const auto& [label, box] : bounds) {
      setVector(box.first, part_of[label]->mutable_bounds_object()->mutable_min());
      setVector(box.second, part_of[label]->mutable_bounds_object()->mutable_max());
    }
  }
  return absl::OkStatus();
}

}  // namespace

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

void ObjectDatabaseService::describe(const storage::SessionInfo& stored, v1::SessionInfo* out) {
  out->set_session_name(stored.name);
  out->set_state(toProto(stored.state));
  out->set_started_unix_s(unixSeconds(stored.started_at));
  out->set_ended_unix_s(unixSeconds(stored.ended_at));
  *out->mutable_intrinsics() = intrinsicsFromJson(stored.intrinsics_json);
  out->set_client_info(stored.client_info);
  // As stored; frames_integrated is what the stored map holds.
  out->set_counters_unknown(!countersFromJson(stored.counters_json, out->mutable_counters()));
  out->mutable_counters()->set_frames_integrated(uint64_t(stored.frames));
  // A session this server runs: its live state and counters.
  if (std::shared_ptr<LiveSession> live = liveSession(stored.name)) {
    std::lock_guard lock(live->mutex);
    out->set_state(live->state);
    out->set_client_info(live->client_info);
    out->set_started_unix_s(live->started_unix_s);
    out->set_ended_unix_s(live->ended_unix_s);
    *out->mutable_counters() = live->counters;
    out->set_counters_unknown(false);
  }
}

grpc::ServerUnaryReactor* ObjectDatabaseService::ListSessions(
    grpc::CallbackServerContext* context, const v1::ListSessionsRequest* request,
    v1::ListSessionsResponse* response) {
  return answerAuthorized(context, [this, request, response]() -> Status {
    OBJDB_ASSIGN_OR_RETURN(const int64_t after, parsePageToken(request->page_token(), 's', 0));
    OBJDB_ASSIGN_OR_RETURN(const std::vector<storage::SessionInfo> stored, store_->sessions());
    const uint32_t limit = pageSize(request->page_size());
    int64_t last = after;
    for (const auto& s : stored) {
      if (s.id <= after) continue;
      if (response->sessions_size() == int(limit)) {
        response->set_next_page_token(pageToken('s', last, 0));
        break;
      }
      describe(s, response->add_sessions());
      last = s.id;
    }
    return absl::OkStatus();
  });
}

grpc::ServerUnaryReactor* ObjectDatabaseService::ListObjects(grpc::CallbackServerContext* context,
                                                             const v1::ListObjectsRequest* request,
                                                             v1::ListObjectsResponse* response) {
  return answerAuthorized(context, [this, request, response]() -> Status {
    const uint64_t filter = std::hash<std::string>()(request->session_name()) * 4 +
                            (request->include_merged() ? 1 : 0) +
                            (request->include_structure() ? 2 : 0);
    OBJDB_ASSIGN_OR_RETURN(const int64_t after,
                           parsePageToken(request->page_token(), 'o', filter));
    if (!request->session_name().empty()) {
      OBJDB_RETURN_IF_ERROR(checkSessionStored(*store_, request->session_name()));
    }
    storage::ModelQuery query;
    query.after_id = after;
    query.limit = pageSize(request->page_size()) + 1;  // one more: is there a next page?
    query.session = request->session_name();
    query.include_merged = request->include_merged();
    query.include_structure = request->include_structure();
    OBJDB_ASSIGN_OR_RETURN(std::vector<storage::ModelSummary> models,
                           store_->modelSummaries(query));
    const bool more = models.size() == query.limit;
    if (more) models.pop_back();
    for (const auto& m : models) {
      v1::ObjectSummary* summary = response->add_objects();
      toProto(m, summary);
      if (!request->include_parts()) continue;
      if (const Status parts = addParts(*store_, m, false, summary->mutable_parts()); !parts.ok()) {
        response->Clear();
        return parts;
      }
    }
    if (more) response->set_next_page_token(pageToken('o', models.back().id, filter));
    return absl::OkStatus();
  });
}

grpc::ServerUnaryReactor* ObjectDatabaseService::GetObject(grpc::CallbackServerContext* context,
                                                           const v1::GetObjectRequest* request,
                                                           v1::ObjectDetail* response) {
  auto run = [this, request, response]() -> Status {
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
    if (found.empty() || found.front().id != id) return noObject(*store_, id);
    const storage::ModelSummary& summary = found.front();
    toProto(summary, response->mutable_summary());
    v1::ObjectStats& stats = *response->mutable_stats();
    std::set<uint64_t> segments;
    for (const auto& o : summary.observations) {
      v1::ObjectPose& pose = *response->add_poses();
      pose.set_session_name(o.session);
      *pose.mutable_t_world_object() = toProto(o.T_world_object);
      pose.set_segment_id(uint64_t(o.raw_segment_id));
      for (const uint32_t part : o.parts) pose.add_parts(part);
      if (o.raw_segment_id > 0) segments.insert(uint64_t(o.raw_segment_id));
    }
    for (uint64_t s : segments) stats.add_segment_ids(s);
    stats.set_num_points(uint32_t(summary.num_points));
    stats.set_num_keypoints(uint32_t(summary.num_keypoints));
    stats.set_voxel_size_m(summary.voxel_size);
    stats.set_num_merges(uint32_t(summary.merges));
    OBJDB_ASSIGN_OR_RETURN(const std::vector<database::MergeRecord> merges,
                           store_->mergeRecordsInto(id));
    for (const auto& m : merges) {
      v1::MergeEvidence& ev = *response->add_merges();
      ev.set_icp_rmse_m(m.icp_rmse_m);
      ev.set_tsdf_rmse_m(m.tsdf_rmse_m);
      ev.set_overlap_voxels(m.tsdf_overlap);
      *ev.mutable_t_into_merged() = toProto(m.T_target_source);
      ev.set_scene_checks(uint32_t(m.scene_checks));
      ev.set_source(m.source);
      // One id space with the poses and the lineage: a segment by its raw segment id.
      std::string session;
      gsm::Label label = 0;
      int64_t object = 0;
      if (database::parseSegmentSource(m.source, &session, &label)) {
        auto row = store_->rawSegmentId({session, label});
        if (row.ok() && *row > 0) {
          ev.set_source_segment_id(uint64_t(*row));
          ev.set_source(absl::StrFormat("segment %d (%s/%d)", *row, session, label));
        }
      } else if (database::parseModelSource(m.source, &object)) {
        ev.set_source_object_id(uint64_t(object));
      }
    }
    if (summary.state != "active") return absl::OkStatus();  // merged: its geometry moved on
    OBJDB_ASSIGN_OR_RETURN(const std::shared_ptr<const model::ObjectModel> model, store_->model(id));
    const size_t per_block = size_t(std::pow(model->grid.voxelsPerSide(), 3));
    stats.set_num_voxels(uint32_t(model->grid.numBlocks() * per_block));
    if (request->include_mesh()) {
      toProto(tsdf::extractMesh(model->grid, options_.params.tsdf.mesh_min_weight),
              response->mutable_mesh());
    }
    if (request->include_cloud()) toProto(model->cloud, response->mutable_cloud());
    if (request->include_parts()) {
      OBJDB_RETURN_IF_ERROR(addParts(*store_, summary, true, response->mutable_parts()));
    }
    const size_t bytes = response->ByteSizeLong();
    if (bytes > options_.max_send_message_bytes) {
      return absl::ResourceExhaustedError(absl::StrFormat(
          "object %d with its %s is %d bytes, above the server's message limit of %d bytes; ask "
          "for less (include_mesh / include_cloud / include_parts)",
          id, request->include_mesh() ? "mesh" : request->include_cloud() ? "cloud" : "parts",
          bytes, options_.max_send_message_bytes));
    }
    return absl::OkStatus();
  };
  return answerAuthorized(context, [run, response] {
    const Status status = run();
    if (!status.ok()) response->Clear();
    return status;
  });
}

// Streams a session's mesh in chunks; the mesh is made on the scene pool's threads.
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
  if (draining_.load()) {
    return new RefusedCall<grpc::ServerWriteReactor<v1::MeshChunk>>(toGrpcStatus(shuttingDown()));
  }
  auto* reactor = new SceneMeshReactor();
  const std::string name = request->session_name();
  const bool completed = request->completed();
  const Status queued = scenes_->submit([this, reactor, name, completed, context] {
    // A deadline or a cancel stops the work where it is checked: before it starts (it may have
    // waited in the pool's queue), between the models of a completion, and before and after the
    // meshing.
    const auto stopIfCancelled = [&](const char* where) -> Status {
      if (!context->IsCancelled()) return absl::OkStatus();
      return absl::CancelledError(
          absl::StrFormat("GetSceneMesh of session %s cancelled %s", name, where));
    };
    auto run = [&]() -> StatusOr<std::vector<TriangleMesh>> {
      OBJDB_RETURN_IF_ERROR(stopIfCancelled("before it started"));
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
        OBJDB_ASSIGN_OR_RETURN(
            const tsdf::TsdfLayer full,
            completion::completeScene(*store_, name, options_.params.merging, params.tsdf, nullptr,
                                      [context] { return context->IsCancelled(); }));
        OBJDB_RETURN_IF_ERROR(stopIfCancelled("after the completion, before the meshing"));
        mesh = tsdf::extractMesh(full, params.tsdf.mesh_min_weight);
      } else {
        mesh = tsdf::extractMesh(*scene, params.tsdf.mesh_min_weight);
      }
      OBJDB_RETURN_IF_ERROR(stopIfCancelled("after the meshing"));
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
  if (!queued.ok()) {
    queries_refused_.fetch_add(1);
    reactor->fail(queued);
  }
  return reactor;
}

grpc::ServerUnaryReactor* ObjectDatabaseService::GetStats(grpc::CallbackServerContext* context,
                                                          const v1::GetStatsRequest*,
                                                          v1::GetStatsResponse* response) {
  auto run = [this, response]() -> Status {
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
    response->set_database_size_bytes(uint64_t(store_->diskBytes()));
    response->set_queued_segments(uint32_t(database_queue_->pending()));
    response->set_jobs_cancelled(jobs_cancelled_.load());
    response->set_candidates_skipped(candidates_skipped_.load());
    response->set_scene_checks(scene_checks_.load());
    response->set_candidates_rejected_by_scene(candidates_rejected_by_scene_.load());
    response->set_poses_without_scene(poses_without_scene_.load());
    response->set_merges_same_place(merges_same_place_.load());
    response->set_extractions_deferred(extractions_deferred_.load());
    {
      std::lock_guard lock(timings_mutex_);
      const database::InsertTimings& t = insert_timings_;
      v1::InsertTimingTotals& out = *response->mutable_insert_timings();
      out.set_inserts(inserts_);
      for (const auto& [stage, ms] : database::kInsertStages) {
        if (const auto* field = totalsFieldOf(stage)) {
          out.GetReflection()->SetDouble(&out, field, t.*ms / 1000);
        }
      }
    }
    response->set_sessions_taken_over(sessions_taken_over_.load());
    response->set_leases_lost(leases_lost_.load());
    response->set_segments_unusable(segments_unusable_.load());
    response->set_insert_errors(insert_errors_.load());
    response->set_queries_refused(queries_refused_.load());
    const PublishedScenes::Counters published = published_scenes_.counters();
    response->set_maps_published(published.published);
    response->set_map_publish_s(published.publish_ms / 1000);
    response->set_published_maps_read(published.read);
    return absl::OkStatus();
  };
  return answerAuthorized(context, run);
}

}  // namespace objdb::server
