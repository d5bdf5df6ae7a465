#include "storage/row_codec.h"

#include "absl/container/flat_hash_set.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_split.h"
#include "core/model/global_descriptor.h"

namespace objdb::storage {

Status inRow(const Status& status, std::string_view table, int64_t row, std::string_view column) {
  return annotate(status, absl::StrFormat("%s row %d, column %s", table, row, column));
}

std::string formatParts(const std::vector<uint32_t>& parts) { return absl::StrJoin(parts, ","); }

StatusOr<std::vector<uint32_t>> parseParts(const std::string& text) {
  std::vector<uint32_t> parts;
  if (text.empty()) return parts;
  for (const absl::string_view item : absl::StrSplit(text, ',')) {
    uint32_t label = 0;
    if (!absl::SimpleAtoi(item, &label) || label == 0) {
      return absl::DataLossError(absl::StrFormat("parts \"%s\" is not a list of GSM labels", text));
    }
    parts.push_back(label);
  }
  return parts;
}

SessionInfo readSession(const Row& row) {
  return {.id = row.integer(0), .name = row.text(1), .intrinsics_json = row.text(2),
          .params_json = row.text(3), .started_at = row.text(4), .ended_at = row.text(5),
          .state = sessionStateFromName(row.text(6)), .frames = row.integer(7),
          .client_info = row.text(8), .counters_json = row.text(9)};
}

ModelSummary readModelSummary(const Row& row) {
  return {.id = row.integer(0), .state = row.text(1), .merged_into = row.integer(2),
          .planar = row.integer(3) != 0, .structure = row.integer(14) != 0,
          .num_points = row.integer(4), .num_keypoints = row.integer(5), .voxel_size = row.real(6),
          .bbox_min = Eigen::Vector3d(row.real(7), row.real(8), row.real(9)),
          .bbox_max = Eigen::Vector3d(row.real(10), row.real(11), row.real(12)),
          .observations = {}, .merges = row.integer(13)};
}

StatusOr<database::MergeRecord> readMergeRecord(const Row& row) {
  auto T = decodeTransform(row.bytes(3));
  if (!T.ok()) return inRow(T.status(), "merge_records", row.integer(0), "transform");
  return database::MergeRecord{.target = row.integer(1), .source = row.text(2),
                               .T_target_source = *T, .icp_rmse_m = row.real(4),
                               .tsdf_rmse_m = row.real(5), .tsdf_overlap = size_t(row.integer(6)),
                               .scene_checks = size_t(row.integer(7))};
}

Status readMatchEntry(const Row& row, database::MatchEntry* entry) {
  *entry = {.id = row.integer(0), .planar = row.integer(1) != 0, .structure = row.integer(5) != 0,
            .num_points = size_t(row.integer(2)), .num_keypoints = size_t(row.integer(3)),
            .descriptors = {}, .global = {}, .descriptors_omitted = false, .segments = {}};
  // Active models always have a descriptors blob (of no descriptors, for some): none here is the
  // query without them (kMatchEntryColumnsWithoutDescriptors).
  entry->descriptors_omitted = row.bytes(4).empty();
  if (!entry->descriptors_omitted) {
    auto descriptors = decodeDescriptors(row.bytes(4));
    if (!descriptors.ok()) return inRow(descriptors.status(), "models", entry->id, "descriptors");
    entry->descriptors = std::move(*descriptors);
  }
  if (!row.bytes(6).empty()) {
    auto global = decodeGlobalDescriptor(row.bytes(6));
    if (!global.ok()) return inRow(global.status(), "models", entry->id, "global_descriptor");
    if (global->codebook_version == model::kCodebookVersion &&
        int(global->values.size()) == model::globalDescriptorSize()) {
      entry->global = std::move(global->values);
    }
  }
  return absl::OkStatus();
}

EncodedModel encodeModel(const model::ObjectModel& m, const BlobOptions& options) {
  EncodedModel e;
  e.planar = m.planar;
  e.structure = m.structure;
  e.plane_inlier_ratio = m.plane_inlier_ratio;
  e.num_points = int64_t(m.cloud.points.size());
  e.num_keypoints = int64_t(m.keypoint_indices.size());
  e.voxel_size = m.grid.voxelSize();
  if (!m.cloud.points.empty()) {
    e.bbox_min = e.bbox_max = m.cloud.points.front();
    for (const auto& p : m.cloud.points) {
      e.bbox_min = e.bbox_min.cwiseMin(p);
      e.bbox_max = e.bbox_max.cwiseMax(p);
    }
  }
  e.grid = encodeTsdfGrid(m.grid, options);
  e.surface_voxels = encodeVoxelList(m.surface_voxels, options);
  e.cloud = encodePointCloud(m.cloud, options);
  e.keypoints = encodeIndices(m.keypoint_indices, options);
  e.descriptors = encodeDescriptors(m.descriptors, options);
  if (!m.descriptors.empty()) {
    e.global_descriptor = encodeGlobalDescriptor(
        {model::kCodebookVersion, model::globalDescriptor(m.descriptors)}, options);
  }
  e.timings = m.timings;
  for (const auto& o : m.observations) {
    e.observations.push_back({o.session, int64_t(o.label), encodeTransform(o.T_world_object),
                              encodeTransform(o.T_object_segment)});
  }
  return e;
}

ModelColumns readModelColumns(const Row& row) {
  return {.planar = row.integer(0) != 0, .structure = row.integer(20) != 0,
          .plane_inlier_ratio = row.real(1), .grid = row.bytes(11), .surface_voxels = row.bytes(12),
          .cloud = row.bytes(13), .keypoints = row.bytes(14), .descriptors = row.bytes(15),
          .timings = {row.real(16), row.real(17), row.real(18), row.real(19)}};
}

StatusOr<model::ObjectModel> decodeModel(int64_t id, const ModelColumns& c) {
  auto grid = decodeTsdfGrid(c.grid);
  if (!grid.ok()) return inRow(grid.status(), "models", id, "grid");
  model::ObjectModel m(std::move(*grid));
  m.id = id;
  m.planar = c.planar;
  m.structure = c.structure;
  m.plane_inlier_ratio = float(c.plane_inlier_ratio);
  // Each blob into its member, in column order; the first damaged one fails the model.
  const auto take = [id](auto decoded, const char* column, auto* member) -> Status {
    if (!decoded.ok()) return inRow(decoded.status(), "models", id, column);
    *member = std::move(*decoded);
    return absl::OkStatus();
  };
  OBJDB_RETURN_IF_ERROR(
      take(decodeVoxelList(c.surface_voxels), "surface_voxels", &m.surface_voxels));
  OBJDB_RETURN_IF_ERROR(take(decodePointCloud(c.cloud), "cloud", &m.cloud));
  OBJDB_RETURN_IF_ERROR(take(decodeIndices(c.keypoints), "keypoints", &m.keypoint_indices));
  OBJDB_RETURN_IF_ERROR(take(decodeDescriptors(c.descriptors), "descriptors", &m.descriptors));
  m.timings = c.timings;
  const std::string where = absl::StrFormat("object model %d", id);
  for (uint32_t k : m.keypoint_indices) {
    if (k >= m.cloud.points.size()) {
      return absl::DataLossError(absl::StrFormat(
          "%s: keypoint index %d beyond its %d cloud points", where, k, m.cloud.points.size()));
    }
  }
  if (m.descriptors.size() != m.keypoint_indices.size() && !m.descriptors.empty()) {
    return absl::DataLossError(absl::StrFormat("%s: %d descriptors for %d keypoints", where,
                                               m.descriptors.size(), m.keypoint_indices.size()));
  }
  return m;
}

StatusOr<model::Observation> decodeObservation(const ObservationColumns& c) {
  model::Observation obs;
  obs.session = c.session;
  obs.label = uint32_t(c.label);
  auto T_wo = decodeTransform(c.T_world_object);
  if (!T_wo.ok()) return inRow(T_wo.status(), "observations", c.row, "T_world_object");
  auto T_os = decodeTransform(c.T_object_segment);
  if (!T_os.ok()) return inRow(T_os.status(), "observations", c.row, "T_object_segment");
  obs.T_world_object = *T_wo;
  obs.T_object_segment = *T_os;
  return obs;
}

StatusOr<EncodedRawSegment> encodeRawSegment(const database::RawSegmentRecord& segment,
                                             const BlobOptions& options) {
  if (segment.grid == nullptr) {
    return absl::InvalidArgumentError(absl::StrFormat("raw segment %s/%d has no grid",
                                                      segment.key.session, segment.key.label));
  }
  const std::string offence =
      segmentPartsOffence(segment.parts, segment.voxel_parts, segment.voxels.size());
  if (!offence.empty()) {
    return absl::InvalidArgumentError(absl::StrFormat("raw segment %s/%d: %s",
                                                      segment.key.session, segment.key.label,
                                                      offence));
  }
  EncodedRawSegment e;
  e.pose = encodeTransform(segment.T_world_segment);
  e.grid = encodeTsdfGrid(*segment.grid, options);
  e.voxels = encodeVoxelList(segment.voxels, options);
  if (!segment.voxel_parts.empty()) e.voxel_parts = encodeIndices(segment.voxel_parts, options);
  e.parts = formatParts(segment.parts);
  return e;
}

std::string segmentPartsOffence(const std::vector<uint32_t>& parts,
                                const std::vector<uint32_t>& voxel_parts, size_t voxels) {
  if (voxel_parts.empty()) return "";
  if (voxel_parts.size() != voxels) {
    return absl::StrFormat("%d voxel parts for %d voxels", voxel_parts.size(), voxels);
  }
  const absl::flat_hash_set<uint32_t> known(parts.begin(), parts.end());
  for (const uint32_t part : voxel_parts) {
    if (!known.contains(part)) {
      return absl::StrFormat("a voxel of part %d, which is not one of its parts (%s)", part,
                             parts.empty() ? std::string("none recorded") : formatParts(parts));
    }
  }
  return "";
}

std::optional<ColumnOffence> rawSegmentPartsOffence(const std::string& parts_text,
                                                    std::string_view voxels,
                                                    std::string_view voxel_parts) {
  auto parts = parseParts(parts_text);
  if (!parts.ok()) return ColumnOffence{"parts", std::string(parts.status().message())};
  auto list = decodeVoxelList(voxels);
  if (!list.ok()) return ColumnOffence{"voxels", std::string(list.status().message())};
  auto of = decodeIndices(voxel_parts);
  if (!of.ok()) return ColumnOffence{"voxel_parts", std::string(of.status().message())};
  std::string offence = segmentPartsOffence(*parts, *of, list->size());
  if (offence.empty()) return std::nullopt;
  return ColumnOffence{"voxel_parts", std::move(offence)};
}

RawSegmentColumns readRawSegmentColumns(const Row& row) {
  return {.row = row.integer(0), .pose = row.bytes(1), .grid = row.bytes(2), .voxels = row.bytes(3),
          .extraction_frame = row.integer(4), .observation_depth_m = row.real(5),
          .parts = row.text(6),
          .voxel_parts = row.isNull(7) ? std::nullopt : std::optional(row.bytes(7))};
}

StatusOr<std::shared_ptr<const database::RawSegmentRecord>> decodeRawSegment(
    const database::SegmentKey& key, const RawSegmentColumns& c) {
  const int64_t id = c.row;
  auto record = std::make_shared<database::RawSegmentRecord>();
  record->key = key;
  auto pose = decodeTransform(c.pose);
  if (!pose.ok()) return inRow(pose.status(), "raw_segments", id, "pose");
  record->T_world_segment = *pose;
  auto grid = decodeTsdfGrid(c.grid);
  if (!grid.ok()) return inRow(grid.status(), "raw_segments", id, "grid");
  record->grid = std::make_shared<const tsdf::TsdfLayer>(std::move(*grid));
  auto voxels = decodeVoxelList(c.voxels);
  if (!voxels.ok()) return inRow(voxels.status(), "raw_segments", id, "voxels");
  record->voxels = std::move(*voxels);
  record->extraction_frame = c.extraction_frame;
  record->observation_depth_m = float(c.observation_depth_m);
  auto parts = parseParts(c.parts);
  if (!parts.ok()) return inRow(parts.status(), "raw_segments", id, "parts");
  record->parts = std::move(*parts);
  if (c.voxel_parts) {
    auto voxel_parts = decodeIndices(*c.voxel_parts);
    if (!voxel_parts.ok()) return inRow(voxel_parts.status(), "raw_segments", id, "voxel_parts");
    const std::string offence =
        segmentPartsOffence(record->parts, *voxel_parts, record->voxels.size());
    if (!offence.empty()) {
      return inRow(absl::DataLossError(offence), "raw_segments", id, "voxel_parts");
    }
    record->voxel_parts = std::move(*voxel_parts);
  }
  return std::shared_ptr<const database::RawSegmentRecord>(std::move(record));
}

StatusOr<EncodedMap> encodeMap(const std::string& what, const tsdf::TsdfLayer& map,
                               const gsm::LabelBlocks* labels, const BlobOptions& options) {
  EncodedMap e;
  e.voxel_size = map.voxelSize();
  e.voxels_per_side = map.voxelsPerSide();
  e.tsdf.reserve(map.numBlocks());
  for (const auto& [index, block] : map.blocks()) {
    e.tsdf.push_back({index, encodeTsdfBlock(*block, options)});
  }
  if (labels != nullptr) {
    for (const auto& [index, block] : *labels) {
      OBJDB_ASSIGN_OR_RETURN(EncodedBlock encoded,
                             encodeMapLabels(what, index, block, e.voxels_per_side, options));
      e.labels.push_back(std::move(encoded));
    }
  }
  return e;
}

StatusOr<EncodedBlock> encodeMapLabels(const std::string& what, const tsdf::BlockIndex& index,
                                       const std::vector<uint32_t>& labels,
                                       int64_t voxels_per_side, const BlobOptions& options) {
  const size_t voxels = size_t(voxels_per_side * voxels_per_side * voxels_per_side);
  if (labels.size() != voxels) {
    return absl::InvalidArgumentError(
        absl::StrFormat("%s: label block (%d, %d, %d) has %d labels, the grid's blocks %d", what,
                        index.x(), index.y(), index.z(), labels.size(), voxels));
  }
  return EncodedBlock{index, encodeLabelBlock(labels, options)};
}

StatusOr<std::vector<uint32_t>> decodeMapLabels(std::string_view blob, int64_t voxels_per_side,
                                                const std::string& where) {
  auto decoded = decodeLabelBlock(blob);
  const int64_t n = voxels_per_side * voxels_per_side * voxels_per_side;
  if (decoded.ok() && decoded->size() != size_t(n)) {
    decoded = absl::DataLossError(absl::StrFormat("%d labels, expected %d", decoded->size(), n));
  }
  if (!decoded.ok()) return annotate(decoded.status(), where);
  return decoded;
}

StatusOr<tsdf::TsdfLayer> emptyMap(const std::string& what, double voxel_size,
                                   int64_t voxels_per_side) {
  auto layer = tsdf::TsdfLayer::create(float(voxel_size), int(voxels_per_side));
  if (!layer.ok()) {
    return absl::DataLossError(absl::StrFormat("%s: %s", what, layer.status().message()));
  }
  return layer;
}

const std::vector<BlobColumn>& checkedBlobColumns() {
  static const std::vector<BlobColumn> columns = {
      {"models", "grid", [](auto b) { return decodeTsdfGrid(b).status(); }},
      {"models", "surface_voxels", [](auto b) { return decodeVoxelList(b).status(); }},
      {"models", "cloud", [](auto b) { return decodePointCloud(b).status(); }},
      {"models", "keypoints", [](auto b) { return decodeIndices(b).status(); }},
      {"models", "descriptors", [](auto b) { return decodeDescriptors(b).status(); }},
      {"observations", "T_world_object", [](auto b) { return decodeTransform(b).status(); }},
      {"observations", "T_object_segment", [](auto b) { return decodeTransform(b).status(); }},
      {"raw_segments", "pose", [](auto b) { return decodeTransform(b).status(); }},
      {"raw_segments", "grid", [](auto b) { return decodeTsdfGrid(b).status(); }},
      {"raw_segments", "voxels", [](auto b) { return decodeVoxelList(b).status(); }},
      {"raw_segments", "voxel_parts", [](auto b) { return decodeIndices(b).status(); }},
      {"merge_records", "transform", [](auto b) { return decodeTransform(b).status(); }},
      {"scene_label_blocks", "labels", [](auto b) { return decodeLabelBlock(b).status(); }},
      {"saved_label_blocks", "labels", [](auto b) { return decodeLabelBlock(b).status(); }},
  };
  return columns;
}

const std::vector<StatsTable>& statsTables() {
  static const std::vector<StatsTable> tables = {
      {"sessions", "0"},
      {"scene_blocks", "length(tsdf)"},
      {"scene_label_blocks", "length(labels)"},
      {"saved_blocks", "length(tsdf)"},
      {"saved_label_blocks", "length(labels)"},
      {"raw_segments", "length(pose) + length(grid) + length(voxels)"},
      {"models",
       "COALESCE(length(grid), 0) + COALESCE(length(surface_voxels), 0) + "
       "COALESCE(length(cloud), 0) + COALESCE(length(keypoints), 0) + "
       "COALESCE(length(descriptors), 0)"},
      {"observations", "length(T_world_object) + length(T_object_segment)"},
      {"merge_records", "length(transform)"},
  };
  return tables;
}

Status checkTsdfBlock(std::string_view blob, int64_t voxels_per_side) {
  if (!(voxels_per_side >= 2 && voxels_per_side <= 64)) {
    return absl::DataLossError(absl::StrFormat("map has %d voxels per side", voxels_per_side));
  }
  tsdf::TsdfBlock block(static_cast<int>(voxels_per_side));
  return decodeTsdfBlock(blob, int(voxels_per_side), &block);
}

template <typename Value>
std::optional<Value> SceneCache::get(Entries<Value>* cache, const std::string& key) {
  std::lock_guard lock(mutex_);
  for (auto it = cache->begin(); it != cache->end(); ++it) {
    if (it->first == key) {
      cache->splice(cache->begin(), *cache, it);
      return cache->front().second;
    }
  }
  return std::nullopt;
}

template <typename Value>
void SceneCache::put(Entries<Value>* cache, const std::string& key, Value value) {
  std::lock_guard lock(mutex_);
  cache->remove_if([&key](const auto& entry) { return entry.first == key; });
  cache->emplace_front(key, std::move(value));
  while (cache->size() > max_entries_) cache->pop_back();
}

std::optional<std::shared_ptr<const tsdf::TsdfLayer>> SceneCache::scene(
    const std::string& session) {
  return get(&scenes_, session);
}

std::optional<std::shared_ptr<const gsm::LabelBlocks>> SceneCache::labels(
    const std::string& session) {
  return get(&labels_, session);
}

void SceneCache::putScene(const std::string& session,
                          std::shared_ptr<const tsdf::TsdfLayer> scene) {
  put(&scenes_, session, std::move(scene));
}

void SceneCache::putLabels(const std::string& session,
                           std::shared_ptr<const gsm::LabelBlocks> labels) {
  put(&labels_, session, std::move(labels));
}

}  // namespace objdb::storage
