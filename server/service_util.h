// Small pieces every RPC handler of the ObjectDatabase service shares: the bearer-token check,
// finishing a unary call with a Status, refusing a streaming call, page tokens and sizes.
#pragma once

#include <cstdint>
#include <string>

#include <grpcpp/grpcpp.h>

#include "core/common/status.h"
#include "server/status_convert.h"
#include "storage/store.h"

namespace objdb::server {

inline constexpr uint32_t kDefaultPageSize = 100;
inline constexpr uint32_t kMaxPageSize = 1000;

double nowUnixSeconds();

grpc::ServerUnaryReactor* finishUnary(grpc::CallbackServerContext* context, const Status& status);

// Ends a streaming call at once with `status` (a refused call: no token, wrong token).
template <typename Reactor>
class RefusedCall final : public Reactor {
 public:
  explicit RefusedCall(const grpc::Status& status) { this->Finish(status); }
  void OnDone() override { delete this; }
};

// The call's bearer token against the server's (auth::checkBearer); the first thing every
// handler does.
Status authorize(const grpc::CallbackServerContext* context, const std::string& token);

// Page tokens: "<kind>.<last id>.<filter hash>", opaque to clients.
std::string pageToken(char kind, int64_t last_id, uint64_t filter);
StatusOr<int64_t> parsePageToken(const std::string& token, char kind, uint64_t filter);
uint32_t pageSize(uint32_t requested);
// NOT_FOUND 'no session named "<name>"' (prefixed by "<field>: " when `field` is given) unless
// the store holds session `name`.
Status checkSessionStored(const storage::Store& store, const std::string& name,
                          const std::string& field = "");
// UNAVAILABLE for a call that came while the server drains.
Status shuttingDown();

}  // namespace objdb::server
