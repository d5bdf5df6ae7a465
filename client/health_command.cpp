// `objdb health`: one grpc.health.v1.Health/Check call with a deadline, answer on stdout.
#include <grpcpp/grpcpp.h>

#include <chrono>
#include <cstdio>
#include <memory>
#include <string>

#include "absl/strings/numbers.h"
#include "absl/strings/str_format.h"
#include "client/cli_util.h"
#include "client/commands.h"
#include "client/remote.h"
#include "grpc/health/v1/health.grpc.pb.h"

namespace objdb {
namespace {

constexpr const char* kUsage =
    R"(usage: objdb health [--server HOST:PORT] [--timeout-ms N] [--service NAME]

Asks an objdb server (or any gRPC server with the standard health service) whether it is
serving, and prints SERVING or NOT_SERVING.

)" OBJDB_CONNECTION_USAGE R"(  --timeout-ms N       deadline of the call in milliseconds, 1..3600000 (default 2000)
  --service NAME       ask about one service, e.g. objdb.v1.ObjectDatabase (default: the whole
                       server)
  -h, --help           show this text

exit status: 0 SERVING; 1 NOT_SERVING, unknown service, server unreachable or no answer in time;
2 command-line error.
)";

int usageError(const std::string& message) { return cli::usageError("health", message, kUsage); }

}  // namespace

int runHealthCommand(int argc, char** argv) {
  cli::Connection connection;
  std::string service;
  int timeout_ms = 2000;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "-h" || arg == "--help") {
      std::fputs(kUsage, stdout);
      return 0;
    }
    cli::Connection probe;
    if (arg != "--timeout-ms" && arg != "--service" && !cli::takeConnectionFlag(arg, "", &probe)) {
      return usageError(absl::StrFormat("unknown option \"%s\"", arg));
    }
    if (i + 1 >= argc) return usageError(absl::StrFormat("%s needs a value", arg));
    const std::string value = argv[++i];
    if (cli::takeConnectionFlag(arg, value, &connection)) {
    } else if (arg == "--service") {
      service = value;
    } else if (!absl::SimpleAtoi(value, &timeout_ms) || timeout_ms < 1 || timeout_ms > 3600000) {
      return usageError(
          absl::StrFormat("--timeout-ms must be an integer in [1, 3600000], got \"%s\"", value));
    }
  }
  if (connection.server.empty()) return usageError("--server is empty");
  const std::string& server = connection.server;

  // Health needs no token, but the channel is the one the other commands use (TLS when asked).
  StatusOr<std::shared_ptr<grpc::Channel>> opened = cli::openChannel(connection);
  if (!opened.ok()) return cli::reportError("health", opened.status());
  const std::shared_ptr<grpc::Channel>& channel = *opened;
  auto stub = grpc::health::v1::Health::NewStub(channel);
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::milliseconds(timeout_ms));
  grpc::health::v1::HealthCheckRequest request;
  request.set_service(service);
  grpc::health::v1::HealthCheckResponse response;
  const grpc::Status status = stub->Check(&context, request, &response);

  const std::string what = service.empty() ? server : absl::StrFormat("%s %s", server, service);
  if (!status.ok()) {
    switch (status.error_code()) {
      case grpc::StatusCode::UNAVAILABLE:
        std::fprintf(stderr, "objdb health: cannot reach %s: %s\n", server.c_str(),
                     status.error_message().c_str());
        break;
      case grpc::StatusCode::DEADLINE_EXCEEDED:
        std::fprintf(stderr, "objdb health: no answer from %s within %d ms\n", server.c_str(),
                     timeout_ms);
        break;
      case grpc::StatusCode::NOT_FOUND:
        std::fprintf(stderr, "objdb health: %s does not know the service \"%s\"\n", server.c_str(),
                     service.c_str());
        break;
      case grpc::StatusCode::UNIMPLEMENTED:
        std::fprintf(stderr, "objdb health: %s has no health service\n", server.c_str());
        break;
      default:
        std::fprintf(stderr, "objdb health: %s answered %d: %s\n", server.c_str(),
                     static_cast<int>(status.error_code()), status.error_message().c_str());
        break;
    }
    return 1;
  }
  const std::string name =
      grpc::health::v1::HealthCheckResponse::ServingStatus_Name(response.status());
  std::printf("%s\n", name.c_str());
  if (response.status() != grpc::health::v1::HealthCheckResponse::SERVING) {
    std::fprintf(stderr, "objdb health: %s is %s\n", what.c_str(), name.c_str());
    return 1;
  }
  return 0;
}

}  // namespace objdb
