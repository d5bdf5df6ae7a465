// The one place where absl::Status (used everywhere inside objdb) becomes a grpc::Status.
// Codes map one to one (both follow google.rpc.Code); messages are capped so a runaway message
// (a whole JSON document, a path list) cannot bloat the response.
#pragma once

#include <grpcpp/support/status.h>

#include <cstddef>
#include <string>

#include "core/common/status.h"

namespace objdb {

// Longest status message sent to a client, bytes (TF Serving's cap).
inline constexpr size_t kMaxStatusMessageBytes = 1024;

// Same code, message cut to kMaxStatusMessageBytes (ending in "..." when cut, never inside a
// UTF-8 sequence). OK maps to grpc::Status::OK without a message.
grpc::Status toGrpcStatus(const Status& status);

// `message` unchanged if it fits in `max_bytes`, else its longest prefix that ends on a UTF-8
// character boundary and leaves room for "...", followed by "...".
std::string capStatusMessage(absl::string_view message, size_t max_bytes = kMaxStatusMessageBytes);

}  // namespace objdb
