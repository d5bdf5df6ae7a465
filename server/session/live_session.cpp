#include "server/session/live_session.h"

#include <algorithm>
#include <cctype>
#include <cmath>

#include <nlohmann/json.hpp>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "core/common/params_io.h"
#include "server/proto_convert.h"

namespace objdb::server {
namespace {

constexpr size_t kMaxSessionName = 128;
constexpr size_t kMaxClientInfo = 256;
// Camera positions farther from the world origin are refused: voxel block indices stay small.
constexpr double kMaxWorldExtentM = 10000.0;

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

}  // namespace

StatusOr<std::shared_ptr<LiveSession>> sessionFromHeader(const v1::SessionHeader& header,
                                                         const Params& server_params) {
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
  session->params = server_params;
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
  return session;
}

Status startPipeline(LiveSession& session, int integration_threads) {
  OBJDB_ASSIGN_OR_RETURN(
      segmentation::DepthSegmenter segmenter,
      segmentation::DepthSegmenter::create(session.params.segmentation, session.intrinsics));
  session.segmenter.emplace(std::move(segmenter));
  OBJDB_ASSIGN_OR_RETURN(gsm::Gsm map, gsm::Gsm::create(session.params.tsdf, session.params.gsm,
                                                        session.intrinsics, integration_threads));
  map.setNoiseModel(session.params.model);
  session.map.emplace(std::move(map));
  return absl::OkStatus();
}

PreparedFrame prepareFrame(segmentation::DepthSegmenter& segmenter, const Intrinsics& intrinsics,
                           const v1::Frame& frame) {
  PreparedFrame prepared;
  auto run = [&]() -> Status {
    if (!frame.has_depth()) return absl::InvalidArgumentError("frame.depth is missing");
    OBJDB_ASSIGN_OR_RETURN(prepared.depth,
                           decodeDepth(frame.depth(), intrinsics, &prepared.counts));
    if (frame.has_color()) {
      OBJDB_ASSIGN_OR_RETURN(prepared.color, decodeColor(frame.color(), prepared.depth.width,
                                                         prepared.depth.height));
    }
    OBJDB_ASSIGN_OR_RETURN(prepared.segments,
                           segmenter.segment(prepared.depth,
                                             prepared.color ? &*prepared.color : nullptr,
                                             nullptr, {/*segment_points=*/false}));
    return absl::OkStatus();
  };
  prepared.status = run();
  return prepared;
}

Status integrateFrame(LiveSession& session, const v1::Frame& frame, const PreparedFrame& prepared,
                      v1::FrameAck* ack) {
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
  OBJDB_RETURN_IF_ERROR(prepared.status);
  const ColorImage* color_ptr = prepared.color ? &*prepared.color : nullptr;
  OBJDB_ASSIGN_OR_RETURN(const gsm::GsmFrameResult fused,
                         session.map->integrate(prepared.depth, prepared.segments.labels,
                                                T_world_camera, color_ptr));
  session.has_frame = true;
  session.last_index = frame.index();
  session.last_timestamp = frame.timestamp_s();
  session.frame_indices.push_back(frame.index());
  ack->set_accepted(true);
  v1::FrameCounters& c = *ack->mutable_frame();
  c.set_valid_pixels(uint32_t(fused.tsdf.points_used));
  c.set_missing_pixels(prepared.counts.missing);
  c.set_invalid_pixels(prepared.counts.invalid);
  c.set_out_of_range_pixels(uint32_t(fused.tsdf.out_of_range));
  c.set_segments(uint32_t(prepared.segments.segments.size()));
  return absl::OkStatus();
}

std::vector<RawSegmentJob> extractSegments(LiveSession& session, bool everything,
                                           v1::SegmentExtracted::Reason reason) {
  std::vector<gsm::RawSegment> segments = session.map->extractIdle(everything);
  std::vector<RawSegmentJob> jobs;
  // Withdrawals first: a merged label's survivor, extracted below, must not match the segment
  // it replaces.
  for (const gsm::Label label : session.map->takeWithdrawn()) {
    const tsdf::TsdfLayer& map = session.map->tsdf();
    RawSegmentJob job{gsm::RawSegment{label, Transform::Identity(),
                                      tsdf::TsdfLayer::create(map.voxelSize(), map.voxelsPerSide())
                                          .value(),
                                      {}, 0, 0, 0.0f, {}, {}},
                      reason, session.last_index, nullptr, /*withdraw=*/true};  // label only
    jobs.push_back(std::move(job));
  }
  if (segments.empty()) return jobs;
  auto scene = std::make_shared<const tsdf::TsdfLayer>(session.map->tsdf().snapshot());
  {
    std::lock_guard lock(session.mutex);
    session.scene = scene;
  }
  std::shared_ptr<const MapCopy> publish;
  if (session.publish_scenes != nullptr && session.publish_scenes->load()) {
    publish = std::make_shared<const MapCopy>(copyMap(*session.map, scene));
  }
  for (auto& segment : segments) {
    const size_t frame = size_t(std::max<int64_t>(segment.last_update_frame, 0));
    const uint64_t index =
        frame < session.frame_indices.size() ? session.frame_indices[frame] : session.last_index;
    jobs.push_back({std::move(segment), reason, index, scene, /*withdraw=*/false, publish});
    publish = nullptr;  // once, before the first of them
  }
  return jobs;
}

MapCopy copyMap(const gsm::Gsm& map, std::shared_ptr<const tsdf::TsdfLayer> snapshot) {
  const auto start = std::chrono::steady_clock::now();
  if (snapshot == nullptr) snapshot = std::make_shared<const tsdf::TsdfLayer>(map.tsdf().snapshot());
  MapCopy copy{std::move(snapshot),
               std::make_shared<const gsm::LabelBlocks>(map.mainLabelBlocks()), map.frames()};
  copy.copy_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  return copy;
}

bool sameSegment(const database::RawSegmentRecord& stored, const gsm::RawSegment& segment) {
  if (stored.grid == nullptr || stored.voxels != segment.label_voxels ||
      stored.parts != segment.parts || stored.voxel_parts != segment.voxel_parts ||
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

}  // namespace objdb::server
