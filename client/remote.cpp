#include "client/remote.h"

#include <cstdio>

#include "absl/status/status.h"

namespace objdb::cli {

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
  // gRPC's codes are google.rpc.Code, as Abseil's: one table of names.
  const std::string code = absl::StatusCodeToString(absl::StatusCode(int(status.error_code())));
  std::fprintf(stderr, "objdb %s: %s failed on %s: %s: %s\n", command, what.c_str(),
               server.c_str(), code.c_str(), status.error_message().c_str());
  if (status.error_code() == grpc::StatusCode::UNAVAILABLE) {
    std::fprintf(stderr, "  (is objdb-server running there? start it with objdb-server --listen %s "
                         "--db FILE.sqlite)\n",
                 server.c_str());
  }
  return 1;
}

}  // namespace objdb::cli
