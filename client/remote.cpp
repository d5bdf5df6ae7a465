#include "client/remote.h"

#include <cstdio>

namespace objdb::cli {
namespace {

const char* codeName(grpc::StatusCode code) {
  switch (code) {
    case grpc::StatusCode::OK:
      return "OK";
    case grpc::StatusCode::CANCELLED:
      return "CANCELLED";
    case grpc::StatusCode::INVALID_ARGUMENT:
      return "INVALID_ARGUMENT";
    case grpc::StatusCode::DEADLINE_EXCEEDED:
      return "DEADLINE_EXCEEDED";
    case grpc::StatusCode::NOT_FOUND:
      return "NOT_FOUND";
    case grpc::StatusCode::ALREADY_EXISTS:
      return "ALREADY_EXISTS";
    case grpc::StatusCode::RESOURCE_EXHAUSTED:
      return "RESOURCE_EXHAUSTED";
    case grpc::StatusCode::FAILED_PRECONDITION:
      return "FAILED_PRECONDITION";
    case grpc::StatusCode::UNIMPLEMENTED:
      return "UNIMPLEMENTED";
    case grpc::StatusCode::UNAVAILABLE:
      return "UNAVAILABLE";
    case grpc::StatusCode::DATA_LOSS:
      return "DATA_LOSS";
    case grpc::StatusCode::INTERNAL:
      return "INTERNAL";
    default:
      return "ERROR";
  }
}

}  // namespace

std::unique_ptr<v1::ObjectDatabase::Stub> objectDatabaseStub(const std::string& server) {
  grpc::ChannelArguments arguments;
  arguments.SetMaxReceiveMessageSize(1024 * 1024 * 1024);  // the server's limit decides
  // Plaintext like the server; TLS and tokens come with the authentication issue (R11).
  return v1::ObjectDatabase::NewStub(
      grpc::CreateCustomChannel(server, grpc::InsecureChannelCredentials(), arguments));
}

void setDeadline(grpc::ClientContext* context, double seconds) {
  context->set_deadline(std::chrono::system_clock::now() +
                        std::chrono::milliseconds(int64_t(seconds * 1000.0)));
}

int reportRpcError(const char* command, const std::string& what, const std::string& server,
                   const grpc::Status& status) {
  std::fprintf(stderr, "objdb %s: %s failed on %s: %s: %s\n", command, what.c_str(),
               server.c_str(), codeName(status.error_code()), status.error_message().c_str());
  if (status.error_code() == grpc::StatusCode::UNAVAILABLE) {
    std::fprintf(stderr, "  (is objdb-server running there? start it with objdb-server --listen %s "
                         "--db FILE.sqlite)\n",
                 server.c_str());
  }
  return 1;
}

}  // namespace objdb::cli
