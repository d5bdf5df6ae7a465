#include "core/io/ground_truth.h"

#include <array>
#include <set>

#include <nlohmann/json.hpp>

#include "core/io/image_io.h"
#include "core/io/io_util.h"

namespace objdb::io {
namespace {
namespace fs = std::filesystem;
using nlohmann::json;

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

StatusOr<InstanceImage> readInstanceImage(const fs::path& path, const Intrinsics& intrinsics) {
  OBJDB_ASSIGN_OR_RETURN(InstanceImage instances, readIdPng(path));
  OBJDB_RETURN_IF_ERROR(intrinsics.checkImageSize(instances.width, instances.height,
                                                  absl::StrCat("instances image ", path.string())));
  return instances;
}

}  // namespace objdb::io
