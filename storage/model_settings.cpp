#include "storage/model_settings.h"

#include <string>

#include <nlohmann/json.hpp>

#include "absl/strings/str_format.h"
#include "core/common/params_io.h"

namespace objdb::storage {
namespace {

// The parameters that decide how a model is described, as flat "section.key" → value.
nlohmann::json describingSettings(const nlohmann::json& params) {
  nlohmann::json out = nlohmann::json::object();
  for (const char* section : {"model", "keypoints", "descriptors"}) {
    if (!params.contains(section) || !params[section].is_object()) continue;
    for (const auto& [key, value] : params[section].items()) {
      out[std::string(section) + "." + key] = value;
    }
  }
  // The voxel size and the weight a surface needs to be meshed shape the model's cloud too.
  if (params.contains("tsdf") && params["tsdf"].is_object()) {
    for (const char* key : {"voxel_size_m", "mesh_min_weight"}) {
      if (params["tsdf"].contains(key)) out[std::string("tsdf.") + key] = params["tsdf"][key];
    }
  }
  return out;
}

// Floats are stored as doubles of float values: shown short (0.02, not 0.0199999995529651).
std::string show(const nlohmann::json& value) {
  return value.is_number_float() ? absl::StrFormat("%g", value.get<double>()) : value.dump();
}

}  // namespace

Status checkModelSettings(const std::vector<SessionInfo>& stored, const Params& params) {
  const nlohmann::json ours = describingSettings(nlohmann::json::parse(paramsToJson(params)));
  for (auto it = stored.rbegin(); it != stored.rend(); ++it) {
    const nlohmann::json recorded = nlohmann::json::parse(it->params_json, nullptr, false);
    if (recorded.is_discarded() || !recorded.is_object() || !recorded.contains("descriptors")) {
      continue;
    }
    const nlohmann::json theirs = describingSettings(recorded);
    for (const auto& [key, value] : ours.items()) {
      const auto other = theirs.find(key);
      const std::string stored_value = other == theirs.end() ? "(missing)" : show(*other);
      if (other != theirs.end() && *other == value) continue;
      return absl::FailedPreconditionError(absl::StrFormat(
          "the database's models were described with %s = %s (session %s), these parameters "
          "say %s; models described differently do not match each other. Use the same "
          "settings (--config) as before, or a new database file",
          key, stored_value, it->name, show(value)));
    }
    return absl::OkStatus();
  }
  return absl::OkStatus();
}

}  // namespace objdb::storage
