#include "client/remote.h"

#include <cstdio>
#include <vector>

#include <grpcpp/support/client_interceptor.h>

#include "absl/status/status.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "server/address.h"
#include "server/proto_convert.h"

namespace objdb::cli {

namespace {

// Adds "authorization: Bearer <token>" to every call of a channel. (Call credentials would not
// do: gRPC attaches them only to channels secure enough for them, never to a plaintext one.)
class BearerInterceptor final : public grpc::experimental::Interceptor {
 public:
  explicit BearerInterceptor(const std::string* header) : header_(header) {}
  void Intercept(grpc::experimental::InterceptorBatchMethods* methods) override {
    if (methods->QueryInterceptionHookPoint(
            grpc::experimental::InterceptionHookPoints::PRE_SEND_INITIAL_METADATA)) {
      methods->GetSendInitialMetadata()->insert({auth::kAuthorizationKey, *header_});
    }
    methods->Proceed();
  }

 private:
  const std::string* header_;
};

class BearerInterceptorFactory final
    : public grpc::experimental::ClientInterceptorFactoryInterface {
 public:
  explicit BearerInterceptorFactory(std::string token)
      : header_(std::string(auth::kBearerPrefix) + token) {}
  grpc::experimental::Interceptor* CreateClientInterceptor(
      grpc::experimental::ClientRpcInfo*) override {
    return new BearerInterceptor(&header_);
  }

 private:
  const std::string header_;  // lives as long as the channel (gRPC owns the factory)
};

}  // namespace

bool takeConnectionFlag(const std::string& flag, const std::string& value, Connection* c) {
  if (flag == "--server") {
    c->server = value;
  } else if (flag == "--token-file") {
    c->token_file = value;
  } else if (flag == "--tls-ca") {
    c->tls.ca_file = value;
  } else if (flag == "--tls-cert") {
    c->tls.cert_file = value;
  } else if (flag == "--tls-key") {
    c->tls.key_file = value;
  } else {
    return false;
  }
  return true;
}

StatusOr<std::shared_ptr<grpc::Channel>> openChannel(const Connection& connection) {
  if (connection.server.empty()) return absl::InvalidArgumentError("--server is empty");
  OBJDB_ASSIGN_OR_RETURN(std::shared_ptr<grpc::ChannelCredentials> credentials,
                         auth::channelCredentials(connection.tls));
  grpc::ChannelArguments arguments;
  arguments.SetMaxReceiveMessageSize(1024 * 1024 * 1024);  // the server's limit decides
  std::vector<std::unique_ptr<grpc::experimental::ClientInterceptorFactoryInterface>> interceptors;
  if (!connection.token_file.empty()) {
    if (connection.tls.ca_file.empty()) {
      // Without TLS the token crosses the wire in clear text: only to this machine.
      const StatusOr<ListenAddress> address = parseListenAddress(connection.server);
      if (!address.ok() || !address->loopback) {
        return absl::InvalidArgumentError(absl::StrCat(
            "--token-file without --tls-ca would send the token in clear text to ",
            connection.server, ", which is not a loopback address: add --tls-ca FILE"));
      }
    }
    OBJDB_ASSIGN_OR_RETURN(std::string token, auth::readTokenFile(connection.token_file));
    interceptors.push_back(std::make_unique<BearerInterceptorFactory>(std::move(token)));
  }
  return grpc::experimental::CreateCustomChannelWithInterceptors(
      connection.server, credentials, arguments, std::move(interceptors));
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
  if (status.error_code() == grpc::StatusCode::UNAVAILABLE &&
      absl::StrContains(status.error_message(), "DNS resolution failed")) {
    // Starting a server on a name that does not resolve would not help.
    std::fprintf(stderr, "  (the host name in %s does not resolve: check --server HOST:PORT)\n",
                 server.c_str());
  } else if (status.error_code() == grpc::StatusCode::UNAVAILABLE) {
    std::fprintf(stderr, "  (is objdb-server running there? start it with objdb-server --listen %s "
                         "--db FILE.sqlite; a TLS server needs --tls-ca, and a plaintext one "
                         "none)\n",
                 server.c_str());
  } else if (status.error_code() == grpc::StatusCode::UNAUTHENTICATED) {
    std::fprintf(stderr, "  (the token is missing or not the server's: --token-file FILE)\n");
  }
  return 1;
}

grpc::Status fetchSceneMesh(v1::ObjectDatabase::Stub& stub, const std::string& session,
                            bool completed, double timeout_s, TriangleMesh* mesh, size_t* chunks) {
  grpc::ClientContext context;
  if (timeout_s > 0.0) setDeadline(&context, timeout_s);
  v1::GetSceneMeshRequest request;
  request.set_session_name(session);
  request.set_completed(completed);
  auto reader = stub.GetSceneMesh(&context, request);
  v1::MeshChunk chunk;
  size_t n = 0;
  while (reader->Read(&chunk)) {
    mesh->append(server::meshFromProto(chunk.mesh()));
    ++n;
  }
  if (chunks != nullptr) *chunks = n;
  return reader->Finish();
}

}  // namespace objdb::cli
