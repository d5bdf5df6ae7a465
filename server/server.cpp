#include "server/server.h"

#include <grpcpp/grpcpp.h>
#include <grpcpp/health_check_service_interface.h>

#include <algorithm>
#include <thread>
#include <utility>

#include "core/common/logging.h"
#include "server/auth.h"
#include "server/object_database_service.h"
#include "storage/open_store.h"

namespace objdb {

Status ServerOptions::validate() const {
  StatusOr<ListenAddress> address = parseListenAddress(listen_address);
  if (!address.ok()) return annotate(address.status(), "listen_address");
  OBJDB_RETURN_IF_ERROR(
      auth::checkTlsServerFiles({tls_cert_file, tls_key_file, tls_client_ca_file}));
  const bool tls = !tls_cert_file.empty();
  const bool authenticated = !token_file.empty() || !tls_client_ca_file.empty();
  if (!address->loopback && !(tls && authenticated) && !allow_remote) {
    return absl::InvalidArgumentError(absl::StrCat(
        "listen_address \"", listen_address, "\" is not a loopback address and the server has ",
        !tls ? "no TLS (a token would cross the network in clear text)"
             : "no token and no client certificates (anyone could read and write the database)",
        ": use --tls-cert/--tls-key with --token-file or --tls-client-ca, or set allow_remote "
        "(--allow-remote) to listen there anyway"));
  }
  if (db_path.empty()) return absl::InvalidArgumentError("db_path is empty");
  for (const auto& [name, value] :
       {std::pair{"max_receive_message_bytes", max_receive_message_bytes},
        std::pair{"max_send_message_bytes", max_send_message_bytes}}) {
    if (value < kMinMessageBytes || value > kMaxMessageBytes) {
      return absl::InvalidArgumentError(absl::StrFormat("%s is %d bytes, must be in [%d, %d]", name,
                                                        value, kMinMessageBytes, kMaxMessageBytes));
    }
  }
  if (drain_deadline.count() < 0 || drain_deadline > kMaxDrainDeadline) {
    return absl::InvalidArgumentError(
        absl::StrFormat("drain_deadline is %d ms, must be in [0, %d] ms",
                        static_cast<int64_t>(drain_deadline.count()),
                        static_cast<int64_t>(kMaxDrainDeadline.count())));
  }
  if (keepalive_time < std::chrono::milliseconds(100) || keepalive_time > std::chrono::hours(24) ||
      keepalive_timeout < std::chrono::milliseconds(100) ||
      keepalive_timeout > std::chrono::hours(1)) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "keepalive_time is %d ms and keepalive_timeout %d ms; they must be in [100 ms, 24 h] and "
        "[100 ms, 1 h]",
        static_cast<int64_t>(keepalive_time.count()),
        static_cast<int64_t>(keepalive_timeout.count())));
  }
  if (max_connection_idle.count() != 0 &&
      (max_connection_idle < std::chrono::milliseconds(100) ||
       max_connection_idle > std::chrono::hours(24 * 7))) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "max_connection_idle is %d ms; it must be 0 (never) or in [100 ms, 7 days]",
        static_cast<int64_t>(max_connection_idle.count())));
  }
  if (ended_sessions_kept < 0 || ended_sessions_kept > 100000) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "ended_sessions_kept is %d, must be in [0, 100000]", ended_sessions_kept));
  }
  if (max_open_sessions < 1 || max_open_sessions > kMaxOpenSessions) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "max_open_sessions is %d, must be in [1, %d]", max_open_sessions, kMaxOpenSessions));
  }
  if (query_threads < 1 || query_threads > 64 || query_queue < 1 || query_queue > 100000) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "query_threads is %d (must be in [1, 64]) and query_queue %d (must be in [1, 100000])",
        query_threads, query_queue));
  }
  if (auto_end_after.count() < 0 || auto_end_after > std::chrono::hours(24 * 7)) {
    return absl::InvalidArgumentError(
        absl::StrFormat("auto_end_after is %d ms, must be in [0, one week]",
                        static_cast<int64_t>(auto_end_after.count())));
  }
  if (save_map_every.count() < 0 || save_map_every > std::chrono::hours(24)) {
    return absl::InvalidArgumentError(
        absl::StrFormat("save_map_every is %d ms, must be in [0, one day]",
                        static_cast<int64_t>(save_map_every.count())));
  }
  if (lease_ttl < std::chrono::milliseconds(100) || lease_ttl > std::chrono::hours(1)) {
    return absl::InvalidArgumentError(
        absl::StrFormat("lease_ttl is %d ms, must be in [100 ms, one hour]",
                        static_cast<int64_t>(lease_ttl.count())));
  }
  if (server_id.size() > 200) {
    return absl::InvalidArgumentError(
        absl::StrFormat("server_id has %d characters, at most 200", server_id.size()));
  }
  if (max_pending_events < 1 || max_pending_events > 65536) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "max_pending_events is %d, must be in [1, 65536]", max_pending_events));
  }
  if (slow_reader_timeout.count() < 1 || slow_reader_timeout > std::chrono::hours(24)) {
    return absl::InvalidArgumentError(
        absl::StrFormat("slow_reader_timeout is %d ms, must be in [1 ms, one day]",
                        static_cast<int64_t>(slow_reader_timeout.count())));
  }
  if (segment_queue < 0 || segment_queue > 100000) {
    return absl::InvalidArgumentError(
        absl::StrFormat("segment_queue is %d segments, must be in [0, 100000]", segment_queue));
  }
  if (frame_queue < 1 || frame_queue > 1024) {
    return absl::InvalidArgumentError(
        absl::StrFormat("frame_queue is %d frames, must be in [1, 1024]", frame_queue));
  }
  return annotate(params.validate(), "params");
}

StatusOr<std::unique_ptr<ObjdbServer>> ObjdbServer::start(const ServerOptions& options) {
  OBJDB_RETURN_IF_ERROR(options.validate());
  OBJDB_ASSIGN_OR_RETURN(const ListenAddress address, parseListenAddress(options.listen_address));
  // A port that is taken stops the start before the database file is created or opened.
  OBJDB_RETURN_IF_ERROR(probeListenAddress(address, options.listen_address));
  // The database first: a file that cannot be served stops the start before anything listens.
  OBJDB_ASSIGN_OR_RETURN(std::unique_ptr<storage::Store> store,
                         storage::openStore(options.db_path));

  server::ServiceOptions service_options;
  if (!options.token_file.empty()) {
    OBJDB_ASSIGN_OR_RETURN(service_options.token, auth::readTokenFile(options.token_file));
  }
  OBJDB_ASSIGN_OR_RETURN(
      std::shared_ptr<grpc::ServerCredentials> credentials,
      auth::serverCredentials(
          {options.tls_cert_file, options.tls_key_file, options.tls_client_ca_file}));
  service_options.params = options.params;
  service_options.frame_queue = size_t(options.frame_queue);
  service_options.segment_queue = size_t(options.segment_queue);
  service_options.max_open_sessions = size_t(options.max_open_sessions);
  service_options.ended_sessions_kept = size_t(options.ended_sessions_kept);
  service_options.query_threads = options.query_threads;
  service_options.query_queue = size_t(options.query_queue);
  service_options.auto_end_after = options.auto_end_after;
  service_options.save_map_every = options.save_map_every;
  service_options.server_id = options.server_id;
  service_options.lease_ttl = options.lease_ttl;
  service_options.max_pending_events = size_t(options.max_pending_events);
  service_options.slow_reader_timeout = options.slow_reader_timeout;
  service_options.max_send_message_bytes = size_t(options.max_send_message_bytes);
  OBJDB_ASSIGN_OR_RETURN(std::unique_ptr<server::ObjectDatabaseService> service,
                         server::ObjectDatabaseService::create(service_options, store.get()));
  grpc::EnableDefaultHealthCheckService(true);
  grpc::ServerBuilder builder;
  builder.RegisterService(service.get());
  int port = 0;
  builder.AddListeningPort(options.listen_address, credentials, &port);
  builder.SetMaxReceiveMessageSize(options.max_receive_message_bytes);
  builder.SetMaxSendMessageSize(options.max_send_message_bytes);
  // gRPC sets SO_REUSEPORT by default on Linux, which lets a second server bind a port that is
  // already in use and silently share its traffic. A busy port must be an error instead.
  builder.AddChannelArgument(GRPC_ARG_ALLOW_REUSEPORT, 0);
  // Vanished clients: pings on connections with calls open; idle connections closed.
  builder.AddChannelArgument(GRPC_ARG_KEEPALIVE_TIME_MS, int(options.keepalive_time.count()));
  builder.AddChannelArgument(GRPC_ARG_KEEPALIVE_TIMEOUT_MS,
                             int(options.keepalive_timeout.count()));
  builder.AddChannelArgument(GRPC_ARG_KEEPALIVE_PERMIT_WITHOUT_CALLS, 0);
  builder.AddChannelArgument(GRPC_ARG_HTTP2_MAX_PINGS_WITHOUT_DATA, 0);
  if (options.max_connection_idle.count() > 0) {
    builder.AddChannelArgument(GRPC_ARG_MAX_CONNECTION_IDLE_MS,
                               int(options.max_connection_idle.count()));
  }

  std::unique_ptr<grpc::Server> server = builder.BuildAndStart();
  if (server == nullptr || port == 0) {
    if (server != nullptr) server->Shutdown();
    return absl::UnavailableError(absl::StrCat(
        "cannot listen on ", options.listen_address,
        ": the port is in use, the host is not an address of this machine, binding it is not "
        "permitted", options.tls_cert_file.empty() ? "" : ", or the TLS certificate and key are "
        "not valid PEM or do not belong together"));
  }
  // Sessions a crash left open: interrupted, and ended from their saved maps (before health
  // says SERVING; a call that came in meanwhile is cancelled if this fails).
  if (Status recovered = service->startRecovery(); !recovered.ok()) {
    server->Shutdown(std::chrono::system_clock::now());
    return annotate(recovered, "ending the sessions the last run left open");
  }
  if (grpc::HealthCheckServiceInterface* health = server->GetHealthCheckService()) {
    health->SetServingStatus(true);
    health->SetServingStatus(kObjectDatabaseServiceName, true);
  }
  std::unique_ptr<ObjdbServer> result(new ObjdbServer(
      options, std::move(store), std::move(service), std::move(server), address.host, port));
  logger("server")->info(
      "listening on {} ({}{})", result->address(),
      options.tls_cert_file.empty()
          ? "plaintext"
          : (options.tls_client_ca_file.empty() ? "TLS" : "TLS, client certificates required"),
      options.token_file.empty() ? "" : ", bearer token required");
  return result;
}

ObjdbServer::ObjdbServer(ServerOptions options, std::unique_ptr<storage::Store> store,
                         std::unique_ptr<server::ObjectDatabaseService> service,
                         std::unique_ptr<grpc::Server> server, std::string host, int port)
    : options_(std::move(options)),
      store_(std::move(store)),
      service_(std::move(service)),
      server_(std::move(server)),
      host_(std::move(host)),
      port_(port) {}

ObjdbServer::~ObjdbServer() { shutdown(); }

std::string ObjdbServer::address() const { return absl::StrCat(host_, ":", port_); }

void ObjdbServer::shutdown() {
  std::lock_guard<std::mutex> lock(mutex_);
  if (stopped_) return;
  auto log = logger("server");
  log->info("draining {}: health NOT_SERVING, calls in flight have {} ms to finish", address(),
            options_.drain_deadline.count());
  if (grpc::HealthCheckServiceInterface* health = server_->GetHealthCheckService()) {
    health->SetServingStatus(false);
  }
  service_->beginDrain();
  // A short notice first: calls that arrive now are answered UNAVAILABLE by the service (and
  // health watchers and load balancers see NOT_SERVING), before gRPC stops taking calls, when a
  // call racing the server's GOAWAY would end CANCELLED instead. It counts against the deadline.
  const auto notice = std::min<std::chrono::milliseconds>(kDrainNotice, options_.drain_deadline);
  std::this_thread::sleep_for(notice);
  server_->Shutdown(std::chrono::system_clock::now() + options_.drain_deadline - notice);
  server_->Wait();
  // No call in flight any more: let the session workers and the database queue finish.
  service_->stop();
  // Copy the WAL back into the database file, so a clean stop leaves one self-contained file.
  if (const Status checkpointed = store_->checkpoint(); !checkpointed.ok()) {
    log->warn("checkpoint of {} at shutdown failed: {}", store_->describe(),
              std::string(checkpointed.message()));
  }
  stopped_ = true;
  log->info("stopped serving {}", address());
}

bool ObjdbServer::stopped() const { return stopped_.load(); }

}  // namespace objdb
