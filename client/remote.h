// What the commands that talk to an objdb server share: the channel (plaintext like the server
// until authentication lands; large receive limit for meshes) and one way to report a failed call.
#pragma once

#include <grpcpp/grpcpp.h>

#include <chrono>
#include <memory>
#include <string>

#include "objdb/v1/objdb.grpc.pb.h"

namespace objdb::cli {

inline constexpr const char* kDefaultServer = "127.0.0.1:50051";

std::unique_ptr<v1::ObjectDatabase::Stub> objectDatabaseStub(const std::string& server);

// A deadline `seconds` from now.
void setDeadline(grpc::ClientContext* context, double seconds);

// Prints "objdb <command>: <what> failed on <server>: <CODE>: <message>" to stderr (with a hint
// when the server cannot be reached); returns 1.
int reportRpcError(const char* command, const std::string& what, const std::string& server,
                   const grpc::Status& status);

}  // namespace objdb::cli
