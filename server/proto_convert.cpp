#include "server/proto_convert.h"

#include <cmath>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <unordered_map>

#include <google/protobuf/util/json_util.h>
#include <nlohmann/json.hpp>

#include "absl/strings/str_format.h"
#include "core/io/image_io.h"
#include "core/model/object_model.h"

namespace objdb::server {
namespace {

Status invalid(const std::string& field, const std::string& why) {
  return absl::InvalidArgumentError(absl::StrCat(field, " ", why));
}

// Checks data length and image size shared by every encoding.
Status checkSize(const std::string& field, uint32_t width, uint32_t height, int want_width,
                 int want_height, const char* want_what) {
  if (int64_t(width) != want_width || int64_t(height) != want_height) {
    return invalid(field, absl::StrFormat("is %dx%d, but %s are %dx%d", width, height, want_what,
                                          want_width, want_height));
  }
  return absl::OkStatus();
}

Status checkLength(const std::string& field, size_t got, size_t want, const char* encoding) {
  if (got != want) {
    return invalid(field + ".data", absl::StrFormat("holds %d bytes; %s of this size needs %d",
                                                    got, encoding, want));
  }
  return absl::OkStatus();
}

uint16_t le16(const char* p) {
  const auto* b = reinterpret_cast<const unsigned char*>(p);
  return uint16_t(b[0] | (b[1] << 8));
}

float le32f(const char* p) {
  const auto* b = reinterpret_cast<const unsigned char*>(p);
  const uint32_t bits = uint32_t(b[0]) | (uint32_t(b[1]) << 8) | (uint32_t(b[2]) << 16) |
                        (uint32_t(b[3]) << 24);
  float value;
  std::memcpy(&value, &bits, sizeof value);
  return value;
}


}  // namespace

void setVector(const Eigen::Vector3d& v, v1::Vector3* out) {
  out->set_x(v.x());
  out->set_y(v.y());
  out->set_z(v.z());
}

v1::Pose toProto(const Transform& T) {
  const TumPose p = tumPoseFromTransform(T, 0.0);
  v1::Pose out;
  out.set_x(p.t.x());
  out.set_y(p.t.y());
  out.set_z(p.t.z());
  out.set_qx(p.q_xyzw[0]);
  out.set_qy(p.q_xyzw[1]);
  out.set_qz(p.q_xyzw[2]);
  out.set_qw(p.q_xyzw[3]);
  return out;
}

StatusOr<Transform> fromProto(const v1::Pose& pose, const std::string& field) {
  auto T = transformFromTranslationQuaternion({pose.x(), pose.y(), pose.z()},
                                              {pose.qx(), pose.qy(), pose.qz(), pose.qw()});
  if (!T.ok()) return invalid(field, std::string(T.status().message()));
  return T;
}

v1::Intrinsics toProto(const Intrinsics& intrinsics) {
  v1::Intrinsics out;
  out.set_width(uint32_t(intrinsics.width));
  out.set_height(uint32_t(intrinsics.height));
  out.set_fx(intrinsics.fx);
  out.set_fy(intrinsics.fy);
  out.set_cx(intrinsics.cx);
  out.set_cy(intrinsics.cy);
  return out;
}

StatusOr<Intrinsics> fromProto(const v1::Intrinsics& intrinsics, const std::string& field) {
  if (intrinsics.width() > uint32_t(kMaxImageSide) || intrinsics.height() > uint32_t(kMaxImageSide)) {
    return invalid(field, absl::StrFormat("are %dx%d pixels; each side must be 1..%d",
                                          intrinsics.width(), intrinsics.height(), kMaxImageSide));
  }
  Intrinsics out;
  out.width = int(intrinsics.width());
  out.height = int(intrinsics.height());
  out.fx = intrinsics.fx();
  out.fy = intrinsics.fy();
  out.cx = intrinsics.cx();
  out.cy = intrinsics.cy();
  if (Status valid = out.validate(); !valid.ok()) return invalid(field, std::string(valid.message()));
  return out;
}

v1::Intrinsics intrinsicsFromJson(const std::string& json) {
  v1::Intrinsics out;
  const nlohmann::json j = nlohmann::json::parse(json, nullptr, false);
  if (j.is_discarded() || !j.is_object()) return out;
  auto number = [&j](const char* key) {
    const auto it = j.find(key);
    return it != j.end() && it->is_number() ? it->get<double>() : 0.0;
  };
  out.set_width(uint32_t(number("width")));
  out.set_height(uint32_t(number("height")));
  out.set_fx(number("fx"));
  out.set_fy(number("fy"));
  out.set_cx(number("cx"));
  out.set_cy(number("cy"));
  return out;
}

StatusOr<DepthImage> decodeDepth(const v1::DepthImage& depth, const Intrinsics& intrinsics,
                                 DepthCounts* counts) {
  const std::string field = "frame.depth";
  OBJDB_RETURN_IF_ERROR(checkSize(field, depth.width(), depth.height(), intrinsics.width,
                                  intrinsics.height, "the session's intrinsics"));
  const size_t pixels = size_t(intrinsics.width) * size_t(intrinsics.height);
  const double scale = depth.metres_per_unit();
  const std::string& data = depth.data();
  *counts = {};
  auto needScale = [&]() -> Status {
    if (!std::isfinite(scale) || scale <= 0.0) {
      return invalid(field + ".metres_per_unit",
                     absl::StrFormat("is %g; %s depth needs a finite scale > 0 (0.001 for "
                                     "millimetres)",
                                     scale, v1::DepthImage::Encoding_Name(depth.encoding())));
    }
    return absl::OkStatus();
  };
  // Sensor units → metres as every dataset reader converts them (depthFromRaw).
  auto fromRaw = [&](const RawDepthImage& raw) -> StatusOr<DepthImage> {
    for (uint16_t sample : raw.data) counts->missing += sample == 0 ? 1 : 0;
    return depthFromRaw(raw, scale);
  };
  switch (depth.encoding()) {
    case v1::DepthImage::UINT16: {
      OBJDB_RETURN_IF_ERROR(needScale());
      OBJDB_RETURN_IF_ERROR(checkLength(field, data.size(), pixels * 2, "UINT16 depth"));
      RawDepthImage raw(intrinsics.width, intrinsics.height);
      for (size_t i = 0; i < pixels; ++i) raw.data[i] = le16(data.data() + 2 * i);
      return fromRaw(raw);
    }
    case v1::DepthImage::PNG16: {
      OBJDB_RETURN_IF_ERROR(needScale());
      auto raw = io::decodeUint16Png(data, field + ".data", intrinsics.width, intrinsics.height);
      if (!raw.ok()) return raw.status();  // names frame.depth.data
      return fromRaw(*raw);
    }
    case v1::DepthImage::FLOAT32: {
      if (scale != 0.0) {
        return invalid(field + ".metres_per_unit",
                       absl::StrFormat("is %g; it must be 0 (unset) for FLOAT32 depth, which is "
                                       "in metres",
                                       scale));
      }
      OBJDB_RETURN_IF_ERROR(checkLength(field, data.size(), pixels * 4, "FLOAT32 depth"));
      DepthImage out(intrinsics.width, intrinsics.height, 0.0f);
      for (size_t i = 0; i < pixels; ++i) {
        const float d = le32f(data.data() + 4 * i);
        if (d == 0.0f || std::isnan(d)) {
          ++counts->missing;
        } else if (d < 0.0f || std::isinf(d)) {
          ++counts->invalid;
        } else {
          out.data[i] = d;
        }
      }
      return out;
    }
    default:
      return invalid(field + ".encoding",
                     absl::StrFormat("is %d; use UINT16, FLOAT32 or PNG16", int(depth.encoding())));
  }
}

StatusOr<ColorImage> decodeColor(const v1::ColorImage& color, int width, int height) {
  const std::string field = "frame.color";
  OBJDB_RETURN_IF_ERROR(
      checkSize(field, color.width(), color.height(), width, height, "the depth image's sides"));
  const std::string& data = color.data();
  switch (color.encoding()) {
    case v1::ColorImage::RGB8: {
      const size_t pixels = size_t(width) * size_t(height);
      OBJDB_RETURN_IF_ERROR(checkLength(field, data.size(), pixels * 3, "RGB8 colour"));
      ColorImage out(width, height);
      std::memcpy(out.data.data(), data.data(), pixels * 3);
      return out;
    }
    case v1::ColorImage::PNG:
    case v1::ColorImage::JPEG: {
      auto image = io::decodeColorImage(data, field + ".data", width, height);
      return image;  // errors name frame.color.data
    }
    default:
      return invalid(field + ".encoding",
                     absl::StrFormat("is %d; use RGB8, PNG or JPEG", int(color.encoding())));
  }
}

v1::DepthImage encodeDepth(const DepthImage& depth) {
  v1::DepthImage out;
  out.set_width(uint32_t(depth.width));
  out.set_height(uint32_t(depth.height));
  out.set_encoding(v1::DepthImage::FLOAT32);
  std::string& data = *out.mutable_data();
  data.resize(depth.data.size() * 4);
  for (size_t i = 0; i < depth.data.size(); ++i) {
    uint32_t bits;
    std::memcpy(&bits, &depth.data[i], 4);
    for (int b = 0; b < 4; ++b) data[4 * i + size_t(b)] = char((bits >> (8 * b)) & 0xFF);
  }
  return out;
}

v1::ColorImage encodeColor(const ColorImage& color) {
  static_assert(sizeof(Rgb8) == 3);
  v1::ColorImage out;
  out.set_width(uint32_t(color.width));
  out.set_height(uint32_t(color.height));
  out.set_encoding(v1::ColorImage::RGB8);
  out.set_data(std::string(reinterpret_cast<const char*>(color.data.data()), color.data.size() * 3));
  return out;
}

namespace {

std::vector<Eigen::Vector3f> vectorsOf(const google::protobuf::RepeatedField<float>& values) {
  std::vector<Eigen::Vector3f> out(size_t(values.size()) / 3);
  for (size_t i = 0; i < out.size(); ++i) {
    out[i] = {values[int(3 * i)], values[int(3 * i + 1)], values[int(3 * i + 2)]};
  }
  return out;
}

std::vector<Rgb8> colorsOf(const std::string& bytes, size_t n) {
  if (bytes.size() != 3 * n) return {};
  std::vector<Rgb8> out(n);
  std::memcpy(out.data(), bytes.data(), bytes.size());
  return out;
}

// Mesh vertices or cloud points with their normals and colours, from their proto fields (normals
// or colours of another count are dropped) and to them (those only with one per point).
void pointsFromProto(const google::protobuf::RepeatedField<float>& points,
                     const google::protobuf::RepeatedField<float>& normals,
                     const std::string& colors, std::vector<Eigen::Vector3f>* out_points,
                     std::vector<Eigen::Vector3f>* out_normals, std::vector<Rgb8>* out_colors) {
  *out_points = vectorsOf(points);
  *out_normals = vectorsOf(normals);
  if (out_normals->size() != out_points->size()) out_normals->clear();
  *out_colors = colorsOf(colors, out_points->size());
}

void pointsToProto(const std::vector<Eigen::Vector3f>& points,
                   const std::vector<Eigen::Vector3f>& normals, const std::vector<Rgb8>& colors,
                   google::protobuf::RepeatedField<float>* out_points,
                   google::protobuf::RepeatedField<float>* out_normals, std::string* out_colors) {
  const auto add = [](const std::vector<Eigen::Vector3f>& vectors,
                      google::protobuf::RepeatedField<float>* out) {
    out->Reserve(int(vectors.size() * 3));
    for (const auto& v : vectors) {
      for (int k = 0; k < 3; ++k) out->Add(v[k]);
    }
  };
  add(points, out_points);
  if (normals.size() == points.size()) add(normals, out_normals);
  if (colors.size() == points.size() && !colors.empty()) {
    out_colors->assign(reinterpret_cast<const char*>(colors.data()), colors.size() * 3);
  }
}

}  // namespace

TriangleMesh meshFromProto(const v1::Mesh& mesh) {
  TriangleMesh out;
  pointsFromProto(mesh.vertices(), mesh.normals(), mesh.colors(), &out.vertices, &out.normals,
                  &out.colors);
  for (int i = 0; i + 2 < mesh.triangles_size(); i += 3) {
    out.triangles.emplace_back(int(mesh.triangles(i)), int(mesh.triangles(i + 1)),
                               int(mesh.triangles(i + 2)));
  }
  return out;
}

PointCloud cloudFromProto(const v1::PointCloud& cloud) {
  PointCloud out;
  pointsFromProto(cloud.points(), cloud.normals(), cloud.colors(), &out.points, &out.normals,
                  &out.colors);
  return out;
}

void toProto(const TriangleMesh& mesh, v1::Mesh* out) {
  out->Clear();
  pointsToProto(mesh.vertices, mesh.normals, mesh.colors, out->mutable_vertices(),
                out->mutable_normals(), out->mutable_colors());
  out->mutable_triangles()->Reserve(int(mesh.triangles.size() * 3));
  for (const auto& t : mesh.triangles) {
    for (int k = 0; k < 3; ++k) out->add_triangles(uint32_t(t[k]));
  }
}

void toProto(const PointCloud& cloud, v1::PointCloud* out) {
  out->Clear();
  pointsToProto(cloud.points, cloud.normals, cloud.colors, out->mutable_points(),
                out->mutable_normals(), out->mutable_colors());
}

std::vector<TriangleMesh> splitMesh(const TriangleMesh& mesh, size_t max_bytes) {
  const bool normals = mesh.normals.size() == mesh.vertices.size();
  const bool colors = !mesh.colors.empty() && mesh.colors.size() == mesh.vertices.size();
  // Serialised size: 4 bytes per float and per (varint, at most 5) index, plus a margin.
  const size_t vertex_bytes = 12 + (normals ? 12 : 0) + (colors ? 3 : 0);
  const size_t triangle_bytes = 15;
  std::vector<TriangleMesh> chunks;
  TriangleMesh chunk;
  std::unordered_map<int, int> local;
  size_t bytes = 0;
  auto flush = [&]() {
    if (chunk.triangles.empty()) return;
    chunks.push_back(std::move(chunk));
    chunk = TriangleMesh();
    local.clear();
    bytes = 0;
  };
  for (const auto& t : mesh.triangles) {
    if (bytes + 3 * vertex_bytes + triangle_bytes > max_bytes) flush();
    Eigen::Vector3i mapped;
    for (int k = 0; k < 3; ++k) {
      const auto [it, added] = local.emplace(t[k], int(chunk.vertices.size()));
      if (added) {
        chunk.vertices.push_back(mesh.vertices[size_t(t[k])]);
        if (normals) chunk.normals.push_back(mesh.normals[size_t(t[k])]);
        if (colors) chunk.colors.push_back(mesh.colors[size_t(t[k])]);
        bytes += vertex_bytes;
      }
      mapped[k] = it->second;
    }
    chunk.triangles.push_back(mapped);
    bytes += triangle_bytes;
  }
  flush();
  return chunks;
}

double unixSeconds(const std::string& iso8601_utc) {
  std::tm tm{};
  double seconds = 0.0;
  if (std::sscanf(iso8601_utc.c_str(), "%d-%d-%dT%d:%d:%lf", &tm.tm_year, &tm.tm_mon, &tm.tm_mday,
                  &tm.tm_hour, &tm.tm_min, &seconds) != 6) {
    return 0.0;
  }
  tm.tm_year -= 1900;
  tm.tm_mon -= 1;
  tm.tm_sec = 0;
  return double(timegm(&tm)) + seconds;
}

v1::SessionState toProto(storage::SessionState state) {
  switch (state) {
    case storage::SessionState::kOpen:
      return v1::SESSION_STATE_OPEN;
    case storage::SessionState::kEnded:
      return v1::SESSION_STATE_ENDED;
    case storage::SessionState::kInterrupted:
      return v1::SESSION_STATE_INTERRUPTED;
  }
  return v1::SESSION_STATE_UNSPECIFIED;
}

void toProto(const storage::ModelSummary& model, v1::ObjectSummary* out) {
  out->set_id(uint64_t(model.id));
  out->set_state(model.state == "merged" ? v1::OBJECT_STATE_MERGED : v1::OBJECT_STATE_ACTIVE);
  out->set_merged_into_id(uint64_t(model.merged_into));
  for (const auto& o : model.observations) {
    bool seen = false;
    for (const auto& name : out->session_names()) seen = seen || name == o.session;
    if (!seen) out->add_session_names(o.session);
  }
  out->set_num_poses(uint32_t(model.observations.size()));
  std::vector<std::pair<std::string, Transform>> poses;
  for (const auto& o : model.observations) poses.emplace_back(o.session, o.T_world_object);
  // The bounds' middle is model::placeCentre of the stored cloud.
  out->set_num_places(
      uint32_t(model::countPlaces(poses, 0.5 * (model.bbox_min + model.bbox_max))));
  setVector(model.bbox_min, out->mutable_bounds_object()->mutable_min());
  setVector(model.bbox_max, out->mutable_bounds_object()->mutable_max());
  out->set_planar(model.planar);
  out->set_structure(model.structure);
}

void toProto(const database::CandidateResult& r, v1::MergeEvidence* ev) {
  ev->set_icp_rmse_m(r.registration.icp_rmse);
  ev->set_tsdf_rmse_m(r.model_verdict.agreement.rmse);
  ev->set_overlap_voxels(r.model_verdict.agreement.overlap);
  ev->set_non_overlap_voxels(r.model_verdict.agreement.compared - r.model_verdict.agreement.overlap);
  *ev->mutable_t_into_merged() = toProto(r.registration.T_target_source);
  ev->set_scene_checks(uint32_t(r.scene_checks));
  ev->set_scene_rmse_max_m(r.scene_rmse_max);
  ev->set_scene_overlap_min_voxels(r.scene_overlap_min);
  ev->set_same_place(r.same_place);
  ev->set_colour_distance(r.colour.median_distance);
  ev->set_colour_pairs(r.colour.pairs);
  ev->set_colour_chromatic_pairs(r.colour.chromatic_pairs);
  ev->set_loosened(r.loosened);
}

v1::ObjectEvent removedEvent(int64_t removed, int64_t now_in, uint64_t segment_id) {
  v1::ObjectEvent e;
  e.set_kind(v1::ObjectEvent::REMOVED);
  e.set_object_id(uint64_t(removed));
  e.set_into_object_id(uint64_t(now_in));
  e.set_segment_id(segment_id);
  return e;
}

std::vector<v1::ObjectEvent> objectEvents(const database::InsertReport& report,
                                          uint64_t segment_id) {
  std::vector<v1::ObjectEvent> events;
  if (report.unusable) {
    if (report.removed_model != 0) {
      events.push_back(removedEvent(report.removed_model, 0, segment_id));
    }
    return events;
  }
  v1::ObjectEvent& o = events.emplace_back();
  o.set_segment_id(segment_id);
  if (report.merged) {
    o.set_kind(v1::ObjectEvent::MERGED);
    o.set_into_object_id(uint64_t(report.model_id));
    for (const auto& r : report.results) {
      if (!r.accepted || r.model_id != report.model_id) continue;
      toProto(r, o.mutable_evidence());
      break;
    }
  } else {
    o.set_kind(v1::ObjectEvent::CREATED);
    o.set_object_id(uint64_t(report.model_id));
  }
  // The segment's earlier version emptied its old object: after the segment's own event, so the
  // object it moved to is known.
  if (report.removed_model != 0) {
    events.push_back(removedEvent(report.removed_model, report.model_id, segment_id));
  }
  for (const auto& r : report.co_accepted) {
    if (!r.accepted) continue;
    v1::ObjectEvent& j = events.emplace_back();
    j.set_kind(v1::ObjectEvent::MERGED);
    j.set_object_id(uint64_t(r.model_id));
    j.set_into_object_id(uint64_t(report.model_id));
    j.set_segment_id(segment_id);
    toProto(r, j.mutable_evidence());
  }
  return events;
}

std::string countersJson(const v1::SessionCounters& counters) {
  google::protobuf::util::JsonPrintOptions options;
  options.preserve_proto_field_names = true;
  std::string out;
  (void)google::protobuf::util::MessageToJsonString(counters, &out, options);
  return out;
}

bool countersFromJson(const std::string& json, v1::SessionCounters* counters) {
  if (json.empty()) return false;
  google::protobuf::util::JsonParseOptions options;
  options.ignore_unknown_fields = true;
  return google::protobuf::util::JsonStringToMessage(json, counters, options).ok();
}

}  // namespace objdb::server
