#include "core/io/objdb_dataset.h"

#include <cmath>
#include <set>

#include <nlohmann/json.hpp>

#include "core/common/logging.h"
#include "core/io/image_io.h"
#include "core/io/io_util.h"
#include "core/io/tum_dataset.h"

namespace objdb::io {
namespace {
namespace fs = std::filesystem;
using nlohmann::json;

constexpr const char* kScaleKey = "depth_scale_m";
constexpr double kDefaultMetresPerUnit = 0.001;

std::string frameFileName(size_t index) { return absl::StrFormat("%06d.png", index); }

Status checkScale(double metres_per_unit) {
  if (std::isfinite(metres_per_unit) && metres_per_unit > 0.0) return absl::OkStatus();
  return absl::InvalidArgumentError(absl::StrFormat(
      "depth scale must be finite and > 0 metres per unit (got %g)", metres_per_unit));
}

Status objectError(const fs::path& path, size_t index, absl::string_view field,
                   absl::string_view message) {
  return absl::InvalidArgumentError(
      absl::StrFormat("%s: objects[%d].%s %s", path.string(), index, field, message));
}

Status readNumberArray(const json& value, size_t n, const fs::path& path, size_t index,
                       absl::string_view field, double* out) {
  if (!(value.is_array() && value.size() == n)) {
    return objectError(path, index, field,
                       absl::StrFormat("must be an array of %d numbers (got %s)", n, value.dump()));
  }
  for (size_t k = 0; k < n; ++k) {
    if (!value[k].is_number()) {
      return objectError(
          path, index, field,
          absl::StrFormat("must be an array of %d numbers (got %s)", n, value.dump()));
    }
    out[k] = value[k].get<double>();
  }
  return absl::OkStatus();
}

StatusOr<GroundTruthObject> parseObject(const json& value, const fs::path& path, size_t index) {
  if (!value.is_object()) return objectError(path, index, "", "must be a JSON object");
  GroundTruthObject object;
  const auto id = value.find("id");
  if (id == value.end()) return objectError(path, index, "id", "is missing");
  if (!(id->is_number_integer() && id->get<int64_t>() >= 1 && id->get<int64_t>() <= 65535)) {
    return objectError(path, index, "id",
                       absl::StrCat("must be an integer in 1..65535 (got ", id->dump(), ")"));
  }
  object.id = static_cast<int>(id->get<int64_t>());
  const auto category = value.find("category");
  if (category == value.end()) return objectError(path, index, "category", "is missing");
  if (!category->is_string()) {
    return objectError(path, index, "category",
                       absl::StrCat("must be a string (got ", category->dump(), ")"));
  }
  object.category = category->get<std::string>();
  const auto mesh = value.find("mesh");
  if (mesh != value.end()) {
    if (!mesh->is_string()) {
      return objectError(path, index, "mesh",
                         absl::StrCat("must be a string (got ", mesh->dump(), ")"));
    }
    object.mesh = mesh->get<std::string>();
  }
  const auto structure = value.find("structure");
  if (structure != value.end()) {
    if (!structure->is_boolean()) {
      return objectError(path, index, "structure",
                         absl::StrCat("must be true or false (got ", structure->dump(), ")"));
    }
    object.is_structure = structure->get<bool>();
  }
  const auto pose = value.find("T_world_object");
  if (pose == value.end()) return objectError(path, index, "T_world_object", "is missing");
  if (!(pose->is_object() && pose->contains("t") && pose->contains("q"))) {
    return objectError(path, index, "T_world_object",
                       "must be an object {\"t\": [x, y, z], \"q\": [qx, qy, qz, qw]}");
  }
  Eigen::Vector3d t;
  std::array<double, 4> q{};
  OBJDB_RETURN_IF_ERROR(
      readNumberArray(pose->at("t"), 3, path, index, "T_world_object.t", t.data()));
  OBJDB_RETURN_IF_ERROR(
      readNumberArray(pose->at("q"), 4, path, index, "T_world_object.q", q.data()));
  auto T = transformFromTranslationQuaternion(t, q);
  if (!T.ok()) return objectError(path, index, "T_world_object", T.status().message());
  object.T_world_object = *T;
  return object;
}

}  // namespace

StatusOr<std::vector<GroundTruthObject>> readObjectsJson(const fs::path& path) {
  OBJDB_ASSIGN_OR_RETURN(const json root, internal::readJsonFile(path));
  if (!root.is_object()) {
    return absl::InvalidArgumentError(
        absl::StrCat(path.string(), " must hold a JSON object {\"objects\": [...]}"));
  }
  const auto list = root.find("objects");
  if (list == root.end() || !list->is_array()) {
    return absl::InvalidArgumentError(
        absl::StrCat(path.string(), ": key 'objects' must be present and be an array"));
  }
  std::vector<GroundTruthObject> objects;
  objects.reserve(list->size());
  std::set<int> ids;
  for (size_t i = 0; i < list->size(); ++i) {
    OBJDB_ASSIGN_OR_RETURN(GroundTruthObject object, parseObject((*list)[i], path, i));
    if (!ids.insert(object.id).second) {
      return objectError(path, i, "id", absl::StrCat("repeats id ", object.id));
    }
    objects.push_back(std::move(object));
  }
  return objects;
}

Status writeObjectsJson(const fs::path& path, const std::vector<GroundTruthObject>& objects) {
  nlohmann::ordered_json list = nlohmann::ordered_json::array();
  std::set<int> ids;
  for (size_t i = 0; i < objects.size(); ++i) {
    const GroundTruthObject& o = objects[i];
    const std::string what = absl::StrFormat("writing %s: object %d", path.string(), i);
    if (!(o.id >= 1 && o.id <= 65535)) {
      return absl::InvalidArgumentError(
          absl::StrFormat("%s has id %d; ids must be in 1..65535", what, o.id));
    }
    if (!ids.insert(o.id).second) {
      return absl::InvalidArgumentError(absl::StrFormat("%s repeats id %d", what, o.id));
    }
    OBJDB_RETURN_IF_ERROR(validateTransform(o.T_world_object, what + " T_world_object"));
    const TumPose pose = tumPoseFromTransform(o.T_world_object, 0.0);
    nlohmann::ordered_json entry;
    entry["id"] = o.id;
    entry["category"] = o.category;
    entry["mesh"] = o.mesh;
    entry["structure"] = o.is_structure;
    entry["T_world_object"] = {
        {"t", {pose.t.x(), pose.t.y(), pose.t.z()}},
        {"q", {pose.q_xyzw[0], pose.q_xyzw[1], pose.q_xyzw[2], pose.q_xyzw[3]}}};
    list.push_back(std::move(entry));
  }
  nlohmann::ordered_json root;
  root["objects"] = std::move(list);
  return internal::writeJsonFile(path, root);
}

StatusOr<Intrinsics> readIntrinsicsJson(const fs::path& path, double* metres_per_unit) {
  OBJDB_ASSIGN_OR_RETURN(const auto file, internal::readIntrinsicsFile(path, kScaleKey));
  if (metres_per_unit) *metres_per_unit = file.depth_scale.value_or(kDefaultMetresPerUnit);
  return file.intrinsics;
}

Status writeIntrinsicsJson(const fs::path& path, const Intrinsics& intrinsics,
                           double metres_per_unit) {
  return internal::writeIntrinsicsFile(path, intrinsics, kScaleKey, metres_per_unit);
}

StatusOr<std::unique_ptr<ObjdbDataset>> ObjdbDataset::open(const fs::path& root,
                                                           const DatasetOptions& options) {
  OBJDB_RETURN_IF_ERROR(internal::checkDirectory(root, "objdb dataset folder"));
  auto dataset = std::unique_ptr<ObjdbDataset>(new ObjdbDataset());
  dataset->root_ = root;
  std::error_code ec;
  const fs::path intrinsics_path = root / "intrinsics.json";
  if (fs::exists(intrinsics_path, ec)) {
    OBJDB_ASSIGN_OR_RETURN(dataset->intrinsics_,
                           readIntrinsicsJson(intrinsics_path, &dataset->metres_per_unit_));
  } else if (!options.intrinsics) {
    return absl::NotFoundError(
        absl::StrCat("objdb dataset ", root.string(), " has no intrinsics.json"));
  }
  if (options.intrinsics) {
    OBJDB_RETURN_IF_ERROR(annotate(options.intrinsics->validate(), "intrinsics override"));
    dataset->intrinsics_ = *options.intrinsics;
  }
  OBJDB_ASSIGN_OR_RETURN(dataset->poses_, readTumTrajectory(root / "poses.txt"));
  dataset->has_color_ = fs::is_directory(root / "color", ec);
  dataset->has_instances_ = fs::is_directory(root / "instances", ec);
  const fs::path objects_path = root / "objects.json";
  if (fs::exists(objects_path, ec)) {
    OBJDB_ASSIGN_OR_RETURN(dataset->objects_, readObjectsJson(objects_path));
  }
  logger("io")->debug("opened objdb dataset {}: {} frames{}{}, {} ground-truth objects, {}",
                     root.string(), dataset->poses_.size(), dataset->has_color_ ? ", colour" : "",
                     dataset->has_instances_ ? ", instances" : "", dataset->objects_.size(),
                     toString(dataset->intrinsics_));
  return dataset;
}

StatusOr<Frame> ObjdbDataset::loadFrame(size_t i) const {
  if (!(i < poses_.size())) {
    return absl::OutOfRangeError(absl::StrFormat("frame %d is out of range: %s has %d frames", i,
                                                 root_.string(), poses_.size()));
  }
  const std::string name = frameFileName(i);
  Frame frame;
  frame.index = i;
  frame.timestamp = poses_[i].timestamp;
  OBJDB_ASSIGN_OR_RETURN(frame.T_world_camera, transformFromTumPose(poses_[i]));

  const fs::path depth_path = root_ / "depth" / name;
  OBJDB_ASSIGN_OR_RETURN(const RawDepthImage raw, readUint16Png(depth_path));
  OBJDB_RETURN_IF_ERROR(intrinsics_.checkImageSize(
      raw.width, raw.height, absl::StrCat("depth image ", depth_path.string())));
  OBJDB_ASSIGN_OR_RETURN(frame.depth, depthFromRaw(raw, metres_per_unit_));

  if (has_color_) {
    const fs::path color_path = root_ / "color" / name;
    OBJDB_ASSIGN_OR_RETURN(ColorImage color, readColorImage(color_path));
    OBJDB_RETURN_IF_ERROR(intrinsics_.checkImageSize(
        color.width, color.height, absl::StrCat("colour image ", color_path.string())));
    frame.color = std::move(color);
  }
  if (has_instances_) {
    const fs::path instances_path = root_ / "instances" / name;
    OBJDB_ASSIGN_OR_RETURN(InstanceImage instances, readUint16Png(instances_path));
    OBJDB_RETURN_IF_ERROR(
        intrinsics_.checkImageSize(instances.width, instances.height,
                                   absl::StrCat("instance image ", instances_path.string())));
    frame.instances = std::move(instances);
  }
  return frame;
}

StatusOr<std::unique_ptr<ObjdbDatasetWriter>> ObjdbDatasetWriter::create(
    const fs::path& root, const Intrinsics& intrinsics, double metres_per_unit, bool overwrite) {
  OBJDB_RETURN_IF_ERROR(annotate(intrinsics.validate(), "objdb dataset writer"));
  OBJDB_RETURN_IF_ERROR(annotate(checkScale(metres_per_unit), "objdb dataset writer"));
  std::error_code ec;
  if (fs::exists(root / "poses.txt", ec)) {
    if (!overwrite) {
      return absl::AlreadyExistsError(absl::StrCat(
          root.string(), " already holds an objdb dataset (poses.txt); refusing to overwrite it"));
    }
    // poses.txt goes first: from here on the folder no longer claims to hold a whole dataset.
    for (const char* name : {"poses.txt", "objects.json", "intrinsics.json"}) {
      fs::remove(root / name, ec);
    }
    for (const char* name : {"depth", "color", "instances"}) fs::remove_all(root / name, ec);
  }
  fs::create_directories(root / "depth", ec);
  if (ec) {
    return absl::UnavailableError(
        absl::StrCat("cannot create ", (root / "depth").string(), ": ", ec.message()));
  }
  OBJDB_RETURN_IF_ERROR(writeIntrinsicsJson(root / "intrinsics.json", intrinsics, metres_per_unit));
  auto writer = std::unique_ptr<ObjdbDatasetWriter>(new ObjdbDatasetWriter());
  writer->root_ = root;
  writer->intrinsics_ = intrinsics;
  writer->metres_per_unit_ = metres_per_unit;
  return writer;
}

Status ObjdbDatasetWriter::addFrame(const Frame& frame) {
  if (finished_) {
    return absl::FailedPreconditionError("objdb dataset writer is already finished");
  }
  const size_t index = poses_.size();
  if (frame.index != index) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "frames must be added in order: expected frame %d, got frame %d", index, frame.index));
  }
  if (!std::isfinite(frame.timestamp)) {
    return absl::InvalidArgumentError(
        absl::StrFormat("frame %d has a non-finite timestamp", index));
  }
  // Colour and instances are per dataset: the reader expects them on every frame or none.
  if (index == 0) {
    has_color_ = frame.color.has_value();
    has_instances_ = frame.instances.has_value();
  } else if (frame.color.has_value() != has_color_ ||
             frame.instances.has_value() != has_instances_) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "frame %d has colour=%s instances=%s but frame 0 had colour=%s instances=%s; every "
        "frame of a dataset must carry the same images",
        index, frame.color ? "yes" : "no", frame.instances ? "yes" : "no",
        has_color_ ? "yes" : "no", has_instances_ ? "yes" : "no"));
  }
  OBJDB_RETURN_IF_ERROR(validateFrame(frame, intrinsics_));
  size_t clipped = 0;
  OBJDB_ASSIGN_OR_RETURN(const RawDepthImage raw,
                         depthToRaw(frame.depth, metres_per_unit_, &clipped));
  const std::string name = frameFileName(index);
  OBJDB_RETURN_IF_ERROR(writeUint16Png(root_ / "depth" / name, raw));
  std::error_code ec;
  if (frame.color) {
    fs::create_directories(root_ / "color", ec);
    OBJDB_RETURN_IF_ERROR(writeColorPng(root_ / "color" / name, *frame.color));
  }
  if (frame.instances) {
    fs::create_directories(root_ / "instances", ec);
    OBJDB_RETURN_IF_ERROR(writeUint16Png(root_ / "instances" / name, *frame.instances));
  }
  clipped_ += clipped;
  poses_.push_back(tumPoseFromTransform(frame.T_world_camera, frame.timestamp));
  return absl::OkStatus();
}

Status ObjdbDatasetWriter::finish(const std::vector<GroundTruthObject>& objects) {
  if (finished_) {
    return absl::FailedPreconditionError("objdb dataset writer is already finished");
  }
  if (!objects.empty()) {
    OBJDB_RETURN_IF_ERROR(writeObjectsJson(root_ / "objects.json", objects));
  }
  // poses.txt last: its presence marks a complete dataset.
  OBJDB_RETURN_IF_ERROR(writeTumTrajectory(
      root_ / "poses.txt", poses_,
      "objdb dataset: T_world_camera per frame, line k = frame k (depth/k.png)"));
  finished_ = true;
  if (clipped_ > 0) {
    logger("io")->warn("{}: {} depth values beyond {:.3f} m were written as 0", root_.string(),
                       clipped_, 65535.0 * metres_per_unit_);
  }
  return absl::OkStatus();
}

}  // namespace objdb::io
