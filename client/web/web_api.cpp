#include "client/web/web_api.h"

#include <google/protobuf/util/json_util.h>

#include <chrono>
#include <initializer_list>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "absl/status/status.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "client/merge_sheet.h"
#include "client/remote.h"
#include "client/web/thumbnails.h"
#include "core/io/mesh_io.h"
#include "server/proto_convert.h"

namespace objdb::web {
namespace {

constexpr const char* kPly = "application/octet-stream";

std::string json(const google::protobuf::Message& message) {
  google::protobuf::util::JsonPrintOptions options;
  options.preserve_proto_field_names = true;
  options.always_print_primitive_fields = true;
  std::string out;
  (void)google::protobuf::util::MessageToJsonString(message, &out, options);
  return out;
}

Reply fromGrpc(const grpc::Status& status, const std::string& what) {
  int http = 502;
  switch (status.error_code()) {
    case grpc::StatusCode::NOT_FOUND: http = 404; break;
    case grpc::StatusCode::INVALID_ARGUMENT: http = 400; break;
    case grpc::StatusCode::UNAVAILABLE:
    case grpc::StatusCode::RESOURCE_EXHAUSTED: http = 503; break;
    case grpc::StatusCode::DEADLINE_EXCEEDED: http = 504; break;
    default: break;
  }
  const std::string code =
      absl::StatusCodeToString(static_cast<absl::StatusCode>(status.error_code()));
  return WebApi::error(http, absl::StrCat(what, ": ", status.error_message()), code);
}

// OK when `query` holds only `allowed` keys, each once; else the 400 to send.
bool onlyKeys(const Query& query, std::initializer_list<const char*> allowed, Reply* failed) {
  for (auto it = query.begin(); it != query.end(); ++it) {
    bool known = false;
    for (const char* key : allowed) known = known || it->first == key;
    if (!known) {
      *failed = WebApi::error(400, absl::StrCat("unknown query parameter '", it->first, "' (known: ",
                                                absl::StrJoin(allowed, ", "), ")"));
      return false;
    }
    if (query.count(it->first) > 1) {
      *failed = WebApi::error(400, absl::StrCat("query parameter '", it->first, "' given twice"));
      return false;
    }
  }
  return true;
}

// An optional boolean parameter: absent (false), "0"/"false" or "1"/"true".
bool flag(const Query& query, const char* key, bool* value, Reply* failed) {
  *value = false;
  const auto it = query.find(key);
  if (it == query.end()) return true;
  if (it->second == "1" || it->second == "true") {
    *value = true;
  } else if (!(it->second == "0" || it->second == "false")) {
    *failed = WebApi::error(400, absl::StrCat("query parameter '", key, "' must be 0, 1, true or "
                                              "false (got '", it->second, "')"));
    return false;
  }
  return true;
}

// What a drawing of the model depends on: it is drawn again when the model changes.
std::string versionOf(const v1::ObjectDetail& detail) {
  return absl::StrCat(detail.poses_size(), "/", detail.stats().num_points(), "/",
                      detail.stats().num_voxels(), "/", detail.stats().num_merges());
}

// The model as a merge-sheet row (db_scan.h), from what GetObject (with its cloud) answered.
cli::Row rowOf(const v1::ObjectDetail& detail) {
  cli::Row row;
  const v1::ObjectSummary& s = detail.summary();
  row.summary.id = int64_t(s.id());
  row.summary.planar = s.planar();
  row.summary.structure = s.structure();
  row.summary.num_points = int64_t(detail.stats().num_points());
  const auto& box = s.bounds_object();
  row.summary.bbox_min = Eigen::Vector3d(box.min().x(), box.min().y(), box.min().z());
  row.summary.bbox_max = Eigen::Vector3d(box.max().x(), box.max().y(), box.max().z());
  row.centre = 0.5 * (row.summary.bbox_min + row.summary.bbox_max);
  for (const v1::ObjectPose& pose : detail.poses()) {
    storage::ModelSummary::Pose p;
    p.session = pose.session_name();
    p.raw_segment_id = int64_t(pose.segment_id());
    p.T_world_object = server::fromProto(pose.t_world_object(), "pose").value_or(Transform::Identity());
    row.summary.observations.push_back(p);
    row.placements.push_back(cli::Placement{p.session, p.T_world_object});
  }
  for (const v1::MergeEvidence& m : detail.merges()) {
    database::MergeRecord record;
    record.source = m.source();
    record.icp_rmse_m = m.icp_rmse_m();
    record.tsdf_rmse_m = m.tsdf_rmse_m();
    record.tsdf_overlap = size_t(m.overlap_voxels());
    record.scene_checks = m.scene_checks();
    row.merges.push_back(record);
  }
  const int points = detail.cloud().points_size() / 3;
  const int step = std::max(1, points / int(cli::kMaxScanPoints));
  for (int i = 0; i < points; i += step) {
    const auto& c = detail.cloud().points();
    row.points.emplace_back(c[3 * i], c[3 * i + 1], c[3 * i + 2]);
  }
  return row;
}

bool objectId(const std::string& text, uint64_t* id, Reply* failed) {
  if (!absl::SimpleAtoi(text, id) || *id == 0 || text.find_first_not_of("0123456789") !=
                                                    std::string::npos) {
    *failed = WebApi::error(400, absl::StrCat("'", text, "' is not an object id (a number > 0)"));
    return false;
  }
  return true;
}

}  // namespace

WebApi::WebApi(std::shared_ptr<grpc::Channel> channel, double call_timeout_s,
               double scene_timeout_s, std::map<std::string, std::string> datasets)
    : stub_(v1::ObjectDatabase::NewStub(std::move(channel))),
      call_timeout_s_(call_timeout_s),
      scene_timeout_s_(scene_timeout_s),
      datasets_(std::move(datasets)) {}

Reply WebApi::error(int status, const std::string& message, const std::string& grpc_code) {
  nlohmann::json body = {{"error", message}};
  if (!grpc_code.empty()) body["grpc_code"] = grpc_code;
  return Reply{status, "application/json", body.dump()};
}

void WebApi::deadline(grpc::ClientContext* context, double seconds) const {
  context->set_deadline(std::chrono::system_clock::now() +
                        std::chrono::milliseconds(int64_t(seconds * 1000)));
}

Reply WebApi::sessions(const Query& query) {
  Reply failed;
  if (!onlyKeys(query, {}, &failed)) return failed;
  nlohmann::json out = {{"sessions", nlohmann::json::array()}};
  v1::ListSessionsRequest request;
  request.set_page_size(1000);
  do {
    grpc::ClientContext context;
    deadline(&context, call_timeout_s_);
    v1::ListSessionsResponse page;
    const grpc::Status s = stub_->ListSessions(&context, request, &page);
    if (!s.ok()) return fromGrpc(s, "ListSessions");
    for (const v1::SessionInfo& info : page.sessions()) {
      nlohmann::json session = nlohmann::json::parse(json(info));
      // The objects seen in the session (whole objects, as the gallery lists them).
      size_t objects = 0;
      v1::ListObjectsRequest list;
      list.set_session_name(info.session_name());
      list.set_page_size(1000);
      do {
        grpc::ClientContext c;
        deadline(&c, call_timeout_s_);
        v1::ListObjectsResponse objects_page;
        const grpc::Status ls = stub_->ListObjects(&c, list, &objects_page);
        if (!ls.ok()) return fromGrpc(ls, "ListObjects of session " + info.session_name());
        objects += size_t(objects_page.objects_size());
        list.set_page_token(objects_page.next_page_token());
      } while (!list.page_token().empty());
      session["objects"] = objects;
      out["sessions"].push_back(std::move(session));
    }
    request.set_page_token(page.next_page_token());
  } while (!request.page_token().empty());
  return Reply{200, "application/json", out.dump()};
}

Reply WebApi::objects(const Query& query) {
  Reply failed;
  if (!onlyKeys(query, {"session", "page_size", "page_token", "structure", "merged", "parts"},
                &failed)) {
    return failed;
  }
  v1::ListObjectsRequest request;
  bool structure = false, merged = false, parts = false;
  if (!flag(query, "structure", &structure, &failed) || !flag(query, "merged", &merged, &failed) ||
      !flag(query, "parts", &parts, &failed)) {
    return failed;
  }
  request.set_include_structure(structure);
  request.set_include_merged(merged);
  request.set_include_parts(parts);
  if (auto it = query.find("session"); it != query.end()) request.set_session_name(it->second);
  if (auto it = query.find("page_token"); it != query.end()) request.set_page_token(it->second);
  if (auto it = query.find("page_size"); it != query.end()) {
    uint32_t size = 0;
    if (!absl::SimpleAtoi(it->second, &size) || size > 1000) {
      return error(400, absl::StrCat("page_size must be a number 0..1000 (got '", it->second,
                                     "')"));
    }
    request.set_page_size(size);
  }
  grpc::ClientContext context;
  deadline(&context, call_timeout_s_);
  v1::ListObjectsResponse page;
  const grpc::Status s = stub_->ListObjects(&context, request, &page);
  if (!s.ok()) return fromGrpc(s, "ListObjects");
  return Reply{200, "application/json", json(page)};
}

bool WebApi::getObject(uint64_t id, bool mesh, bool cloud, v1::ObjectDetail* out, Reply* failed) {
  v1::GetObjectRequest request;
  request.set_id(id);
  request.set_include_mesh(mesh);
  request.set_include_cloud(cloud);
  grpc::ClientContext context;
  deadline(&context, call_timeout_s_);
  const grpc::Status s = stub_->GetObject(&context, request, out);
  if (!s.ok()) *failed = fromGrpc(s, absl::StrCat("GetObject ", id));
  return s.ok();
}

Reply WebApi::object(const std::string& id_text, const Query& query) {
  Reply failed;
  uint64_t id = 0;
  if (!onlyKeys(query, {}, &failed) || !objectId(id_text, &id, &failed)) return failed;
  v1::ObjectDetail detail;
  if (!getObject(id, false, false, &detail, &failed)) return failed;
  return Reply{200, "application/json", json(detail)};
}

Reply WebApi::objectGeometry(const std::string& id_text, const std::string& what,
                             const Query& query) {
  Reply failed;
  uint64_t id = 0;
  if (!onlyKeys(query, {}, &failed) || !objectId(id_text, &id, &failed)) return failed;
  const bool mesh = what == "mesh";
  v1::ObjectDetail detail;
  if (!getObject(id, mesh, !mesh, &detail, &failed)) return failed;
  const auto ply = mesh ? io::plyMeshBytes(server::meshFromProto(detail.mesh()))
                        : io::plyCloudBytes(server::cloudFromProto(detail.cloud()));
  if (!ply.ok()) return error(502, std::string(ply.status().message()));
  return Reply{200, kPly, *ply};
}

Reply WebApi::thumbnail(const std::string& id_text, const std::string& view_text,
                        const Query& query) {
  Reply failed;
  uint64_t id = 0;
  if (!onlyKeys(query, {}, &failed) || !objectId(id_text, &id, &failed)) return failed;
  const int view = view_text == "0" ? 0 : view_text == "1" ? 1 : -1;
  if (view < 0) return error(400, absl::StrCat("thumbnail view '", view_text, "': 0 or 1"));
  v1::ObjectDetail detail;
  if (!getObject(id, false, false, &detail, &failed)) return failed;
  const std::string version = versionOf(detail);
  {
    std::lock_guard lock(mutex_);
    const auto it = thumbnails_.find(id);
    if (it != thumbnails_.end() && it->second.version == version) {
      return Reply{200, "image/png", it->second.png[view]};
    }
  }
  if (!getObject(id, true, false, &detail, &failed)) return failed;
  const TriangleMesh mesh = server::meshFromProto(detail.mesh());
  Thumbnails drawn;
  drawn.version = version;
  for (int v = 0; v < kThumbnailViews; ++v) {
    auto png = renderThumbnail(mesh, v);
    if (!png.ok()) {
      return error(absl::IsFailedPrecondition(png.status()) ? 404 : 500,
                   absl::StrCat("object ", id, ": ", png.status().message()));
    }
    drawn.png[v] = std::move(*png);
  }
  std::lock_guard lock(mutex_);
  thumbnails_[id] = drawn;
  return Reply{200, "image/png", drawn.png[view]};
}

Reply WebApi::scene(const std::string& session, const Query& query) {
  Reply failed;
  bool completed = false;
  if (!onlyKeys(query, {"completed"}, &failed) || !flag(query, "completed", &completed, &failed)) {
    return failed;
  }
  TriangleMesh mesh;
  const grpc::Status s =
      cli::fetchSceneMesh(*stub_, session, completed, scene_timeout_s_, &mesh);
  if (!s.ok()) return fromGrpc(s, "GetSceneMesh of session " + session);
  const auto ply = io::plyMeshBytes(mesh);
  if (!ply.ok()) return error(502, std::string(ply.status().message()));
  return Reply{200, kPly, *ply};
}

Reply WebApi::stats(const Query& query) {
  Reply failed;
  if (!onlyKeys(query, {}, &failed)) return failed;
  grpc::ClientContext context;
  deadline(&context, call_timeout_s_);
  v1::GetStatsResponse response;
  const grpc::Status s = stub_->GetStats(&context, v1::GetStatsRequest(), &response);
  if (!s.ok()) return fromGrpc(s, "GetStats");
  return Reply{200, "application/json", json(response)};
}

Reply WebApi::similar(const std::string& id_text, const Query& query) {
  Reply failed;
  uint64_t id = 0;
  if (!onlyKeys(query, {"max_results"}, &failed) || !objectId(id_text, &id, &failed)) return failed;
  v1::MatchRequest request;
  request.set_object_id(id);
  request.set_max_results(10);
  if (const auto it = query.find("max_results"); it != query.end()) {
    uint32_t n = 0;
    if (!absl::SimpleAtoi(it->second, &n) || n > 1000) {
      return error(400, "max_results must be 0..1000 (0: every candidate), got '" + it->second + "'");
    }
    request.set_max_results(n);
  }
  grpc::ClientContext context;
  deadline(&context, scene_timeout_s_);  // a match runs the whole verification: allow a scene's time
  v1::MatchResponse response;
  const grpc::Status s = stub_->Match(&context, request, &response);
  if (!s.ok()) return fromGrpc(s, "Match");
  return Reply{200, "application/json", json(response)};
}

Reply WebApi::viewer(const Query& query) {
  Reply failed;
  if (!onlyKeys(query, {}, &failed)) return failed;
  nlohmann::json datasets = nlohmann::json::array();
  for (const auto& [session, folder] : datasets_) datasets.push_back(session);
  return Reply{200, "application/json", nlohmann::json{{"datasets", datasets}}.dump()};
}

Reply WebApi::sheet(const std::string& id_text, const Query& query) {
  Reply failed;
  uint64_t id = 0;
  if (!onlyKeys(query, {}, &failed) || !objectId(id_text, &id, &failed)) return failed;
  v1::ObjectDetail detail;
  if (!getObject(id, false, false, &detail, &failed)) return failed;
  std::map<std::string, std::string> seen;  // the datasets of the sessions that saw it
  for (const v1::ObjectPose& pose : detail.poses()) {
    if (auto it = datasets_.find(pose.session_name()); it != datasets_.end()) seen.insert(*it);
  }
  if (seen.empty()) {
    return error(404, absl::StrCat("object ", id, " was seen in no session whose dataset this "
                                   "viewer was given (objdb web --dataset SESSION=DIR)"));
  }
  const std::string version = versionOf(detail);
  {
    std::lock_guard lock(mutex_);
    if (auto it = sheets_.find(id); it != sheets_.end() && it->second.first == version) {
      return Reply{200, "image/png", it->second.second};
    }
  }
  if (!getObject(id, false, true, &detail, &failed)) return failed;
  std::vector<cli::Row> rows = {rowOf(detail)};
  std::map<std::string, std::unique_ptr<io::Dataset>> opened;
  if (Status scanned = cli::scanFrames(seen, 1, &rows, &opened); !scanned.ok()) {
    return error(500, std::string(scanned.message()));
  }
  cv::Mat image(cli::kSheetRowHeight, cli::kSheetWidth, CV_8UC3, cv::Scalar(30, 30, 30));
  if (Status drawn = cli::drawSheetRow(rows[0], opened, &image); !drawn.ok()) {
    return error(500, std::string(drawn.message()));
  }
  std::vector<uchar> png;
  if (!cv::imencode(".png", image, png)) return error(500, "PNG encoding failed");
  std::string bytes(png.begin(), png.end());
  std::lock_guard lock(mutex_);
  sheets_[id] = {version, bytes};
  return Reply{200, "image/png", bytes};
}

}  // namespace objdb::web
