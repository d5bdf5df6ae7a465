#include "storage/store.h"

#include <nlohmann/json.hpp>

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

}  // namespace objdb::storage
