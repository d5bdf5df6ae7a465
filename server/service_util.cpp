#include "server/service_util.h"

#include <chrono>
#include <vector>

#include "absl/strings/numbers.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_split.h"
#include "server/auth.h"

namespace objdb::server {

double nowUnixSeconds() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

grpc::ServerUnaryReactor* finishUnary(grpc::CallbackServerContext* context, const Status& status) {
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  reactor->Finish(toGrpcStatus(status));
  return reactor;
}

Status authorize(const grpc::CallbackServerContext* context, const std::string& token) {
  if (token.empty()) return absl::OkStatus();
  const auto& metadata = context->client_metadata();
  const auto it = metadata.find(auth::kAuthorizationKey);
  if (it == metadata.end()) return auth::checkBearer(token, nullptr);
  const std::string value(it->second.data(), it->second.size());
  return auth::checkBearer(token, &value);
}

std::string pageToken(char kind, int64_t last_id, uint64_t filter) {
  return absl::StrFormat("%c.%d.%x", kind, last_id, filter);
}

StatusOr<int64_t> parsePageToken(const std::string& token, char kind, uint64_t filter) {
  if (token.empty()) return int64_t{0};
  const std::vector<std::string> parts = absl::StrSplit(token, '.');
  int64_t last = 0;
  uint64_t hash = 0;
  if (parts.size() != 3 || parts[0].size() != 1 || parts[0][0] != kind ||
      !absl::SimpleAtoi(parts[1], &last) || last < 0 || !absl::SimpleHexAtoi(parts[2], &hash)) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "page_token \"%s\" is not a token this call returned; start with an empty token", token));
  }
  if (hash != filter) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "page_token \"%s\" belongs to a listing with another filter; start again with an empty "
        "token",
        token));
  }
  return last;
}

uint32_t pageSize(uint32_t requested) {
  return requested == 0 ? kDefaultPageSize : std::min(requested, kMaxPageSize);
}

Status shuttingDown() {
  return absl::UnavailableError(
      "the server is shutting down: retry on another server, or once it has restarted");
}

Status checkSessionStored(const storage::Store& store, const std::string& name,
                          const std::string& field) {
  OBJDB_ASSIGN_OR_RETURN(const std::vector<storage::SessionInfo> stored, store.sessions());
  for (const auto& s : stored) {
    if (s.name == name) return absl::OkStatus();
  }
  return absl::NotFoundError(absl::StrFormat("%sno session named \"%s\"",
                                             field.empty() ? "" : field + ": ", name));
}

}  // namespace objdb::server
