#include "storage/store.h"

#include <nlohmann/json.hpp>

#include "absl/strings/str_format.h"

namespace objdb::storage {

const char* sessionStateName(SessionState state) {
  switch (state) {
    case SessionState::kOpen: return "open";
    case SessionState::kEnded: return "ended";
    case SessionState::kInterrupted: return "interrupted";
  }
  return "open";
}

SessionState sessionStateFromName(std::string_view name) {
  if (name == "ended") return SessionState::kEnded;
  if (name == "interrupted") return SessionState::kInterrupted;
  return SessionState::kOpen;
}

std::string intrinsicsJson(const Intrinsics& intrinsics) {
  return nlohmann::json{{"width", intrinsics.width}, {"height", intrinsics.height},
                        {"fx", intrinsics.fx},       {"fy", intrinsics.fy},
                        {"cx", intrinsics.cx},       {"cy", intrinsics.cy}}
      .dump();
}

Status checkOptionRange(std::string_view name, int64_t value, int64_t min, int64_t max) {
  if (value >= min && value <= max) return absl::OkStatus();
  return absl::InvalidArgumentError(
      absl::StrFormat("storage.%s must be in [%d, %d], got %d", name, min, max, value));
}

Status Store::updateSavedMap(const std::string& session, int64_t frames,
                             const tsdf::TsdfLayer& map, const gsm::LabelBlocks& labels,
                             const tsdf::TsdfLayer& /*base_map*/,
                             const gsm::LabelBlocks& /*base_labels*/) {
  return putSavedMap(session, frames, map, labels);
}

}  // namespace objdb::storage
