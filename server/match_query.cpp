// Match ("what is this?"): a cloud, a depth image's masked pixels or a stored object matched
// against the stored objects by the database's own retrieval and checks
// (ObjectDatabase::match, matchModel), on the query pool; nothing is written.
#include <chrono>
#include <string>
#include <utility>

#include "absl/strings/str_format.h"
#include "core/database/query_segment.h"
#include "server/object_database_service.h"
#include "server/proto_convert.h"
#include "server/session/live_session.h"

namespace objdb::server {
namespace {

// The request's cloud, its sizes checked before anything is copied.
StatusOr<database::QueryCloud> queryCloud(const v1::MatchRequest& request) {
  const v1::PointCloud& cloud = request.cloud();
  if (cloud.points_size() % 3 != 0) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "cloud.points: %d values, not x, y, z per point", cloud.points_size()));
  }
  const size_t n = size_t(cloud.points_size()) / 3;
  if (n == 0) return absl::InvalidArgumentError("cloud.points: no points");
  if (n > database::kMaxQueryPoints) {
    return absl::InvalidArgumentError(
        absl::StrFormat("cloud.points: %d points, more than the %d a query may have (one object)",
                        n, database::kMaxQueryPoints));
  }
  if (cloud.normals_size() != 0 && size_t(cloud.normals_size()) != 3 * n) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "cloud.normals: %d values for %d points (3 per point, or none)", cloud.normals_size(), n));
  }
  if (!cloud.colors().empty() && cloud.colors().size() != 3 * n) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "cloud.colors: %d bytes for %d points (3 per point, or none)", cloud.colors().size(), n));
  }
  const PointCloud converted = cloudFromProto(cloud);
  database::QueryCloud query;
  query.points = converted.points;
  query.normals = converted.normals;
  query.colors = converted.colors;
  if (request.has_viewpoint()) {
    const v1::Vector3& v = request.viewpoint();
    query.viewpoint = Eigen::Vector3d(v.x(), v.y(), v.z());
  }
  return query;
}

// The request's depth segment (its images decoded and checked as a frame's).
StatusOr<gsm::RawSegment> depthSegment(const v1::DepthSegment& depth, const TsdfParams& tsdf) {
  database::QueryDepth query;
  OBJDB_ASSIGN_OR_RETURN(query.intrinsics, fromProto(depth.intrinsics(), "depth.intrinsics"));
  DepthCounts counts;
  auto decoded = decodeDepth(depth.depth(), query.intrinsics, &counts);
  if (!decoded.ok()) return annotate(decoded.status(), "depth.depth");
  query.depth = *std::move(decoded);
  ColorImage color;
  if (depth.has_color()) {
    auto c = decodeColor(depth.color(), query.intrinsics.width, query.intrinsics.height);
    if (!c.ok()) return annotate(c.status(), "depth.color");
    color = *std::move(c);
    query.color = &color;
  }
  if (depth.has_t_world_camera()) {
    OBJDB_ASSIGN_OR_RETURN(query.T_world_camera,
                           fromProto(depth.t_world_camera(), "depth.T_world_camera"));
  }
  const size_t pixels = size_t(query.intrinsics.width) * size_t(query.intrinsics.height);
  if (!depth.mask().empty() && depth.mask().size() != pixels) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "depth.mask: %d bytes for a %dx%d image (%d expected, or none)", depth.mask().size(),
        query.intrinsics.width, query.intrinsics.height, pixels));
  }
  query.mask.assign(depth.mask().begin(), depth.mask().end());
  auto segment = database::segmentFromDepth(query, tsdf);
  if (!segment.ok()) return annotate(segment.status(), "depth");
  return segment;
}

void fillAnswer(const database::MatchReport& report, const Transform& T_segment_query,
                uint32_t max_results, v1::MatchResponse* out) {
  out->set_matchable(report.matchable);
  if (report.unusable) {
    out->set_reason("no model: " + report.unusable_reason);
  } else if (report.structure) {
    out->set_reason("room structure (a floor, wall or surface larger than furniture): not matched");
  } else if (report.planar) {
    out->set_reason("planar: one plane gives registration nothing to hold on to; not matched");
  } else if (!report.matchable) {
    out->set_reason("too few surface points or keypoints to be matched");
  }
  out->set_points(uint32_t(report.points));
  out->set_keypoints(uint32_t(report.keypoints));
  out->set_shortlist(uint32_t(report.shortlist.size()));
  out->set_candidates(uint32_t(report.results.size()));
  for (const database::CandidateResult& r : report.results) {
    if (max_results > 0 && uint32_t(out->results_size()) >= max_results) break;
    v1::MatchResult& m = *out->add_results();
    m.set_object_id(uint64_t(r.model_id));
    m.set_accepted(r.accepted);
    m.set_stage(r.stage);
    m.set_reason(r.reason);
    *m.mutable_t_object_query() = toProto(r.registration.T_target_source * T_segment_query);
    toProto(r, m.mutable_evidence());
    m.set_inliers(uint32_t(r.registration.inliers));
  }
}

}  // namespace

grpc::ServerUnaryReactor* ObjectDatabaseService::Match(grpc::CallbackServerContext* context,
                                                       const v1::MatchRequest* request,
                                                       v1::MatchResponse* response) {
  auto run = [this, request, response]() -> Status {
    const auto start = std::chrono::steady_clock::now();
    if (request->has_viewpoint() && !request->has_cloud()) {
      return absl::InvalidArgumentError("viewpoint: only a cloud query has one");
    }
    // Live sessions' poses are verified against their current maps, as an insert's are.
    const bool shared = store_->sharedByServers();
    const database::LiveScenes live =
        [this, shared](const std::string& name) -> std::shared_ptr<const tsdf::TsdfLayer> {
      if (std::shared_ptr<LiveSession> session = liveSession(name)) return session->currentScene();
      return shared ? published_scenes_.scene(name) : nullptr;
    };
    database::MatchReport report;
    Transform T_segment_query = Transform::Identity();
    switch (request->query_case()) {
      case v1::MatchRequest::kObjectId: {
        if (request->object_id() == 0 || request->object_id() > uint64_t(INT64_MAX)) {
          return absl::NotFoundError(
              absl::StrFormat("object_id: no active object %d", request->object_id()));
        }
        auto matched = db_->matchModel(int64_t(request->object_id()), live);
        if (!matched.ok()) return annotate(matched.status(), "object_id");
        report = *std::move(matched);
        break;
      }
      case v1::MatchRequest::kCloud:
      case v1::MatchRequest::kDepth: {
        auto made = [&]() -> StatusOr<gsm::RawSegment> {
          if (!request->has_cloud()) return depthSegment(request->depth(), options_.params.tsdf);
          OBJDB_ASSIGN_OR_RETURN(const database::QueryCloud cloud, queryCloud(*request));
          return database::segmentFromCloud(cloud, options_.params.tsdf);
        }();
        OBJDB_RETURN_IF_ERROR(made.status());
        const gsm::RawSegment& segment = *made;
        T_segment_query = segment.T_world_segment.inverse();
        OBJDB_ASSIGN_OR_RETURN(report, db_->match(segment, live));
        break;
      }
      default:
        return absl::InvalidArgumentError(
            "query: give a cloud, a depth segment or an object_id to match");
    }
    fillAnswer(report, T_segment_query, request->max_results(), response);
    response->set_elapsed_s(
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
    return absl::OkStatus();
  };
  return answerAuthorized(context, std::move(run));
}

}  // namespace objdb::server
