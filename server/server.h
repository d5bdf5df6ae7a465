// The objdb gRPC server: options, listen-address policy, startup and graceful shutdown. Serves
// objdb.v1.ObjectDatabase (server/object_database_service.h) over its store and the
// standard grpc.health.v1 health service (SERVING for "" and "objdb.v1.ObjectDatabase" while up).
#pragma once

#include <atomic>
#include <chrono>
#include <memory>
#include <mutex>
#include <string>

#include "core/common/params.h"
#include "core/common/status.h"
#include "server/address.h"
#include "storage/store.h"

namespace grpc {
class Server;
}  // namespace grpc

namespace objdb {

namespace server {
class ObjectDatabaseService;
}

struct ServerOptions {
  // Where to listen, HOST:PORT; port 0 picks a free port (see ObjdbServer::port()).
  std::string listen_address = "127.0.0.1:50051";
  // A non-loopback address needs TLS with a token or client certificates (below): otherwise
  // anyone who can reach the port could read and write the database (or read the token on the
  // wire). This accepts any address anyway.
  bool allow_remote = false;
  // Bearer token (server/auth.h): when set, every objdb.v1.ObjectDatabase call must carry
  // "authorization: Bearer <token>" or is refused with UNAUTHENTICATED. The health service stays
  // open (it tells only whether the server is up). Read once at start.
  std::string token_file;
  // TLS: PEM certificate chain and key; with a client CA, clients must present a certificate it
  // signed (mutual TLS). Empty = plaintext.
  std::string tls_cert_file;
  std::string tls_key_file;
  std::string tls_client_ca_file;
  // The store, opened at start: a SQLite file (created if missing) or a postgresql:// URI. A
  // corrupt file, an unreachable database, another application's database or a newer schema
  // stops the start with the reason (docs/storage.md).
  std::string db_path = "objdb.sqlite";
  // Largest message accepted / sent, bytes (gRPC's default receive limit of 4 MiB is below one
  // 1280×720 depth + colour frame). Larger messages fail with RESOURCE_EXHAUSTED.
  int max_receive_message_bytes = 16 * 1024 * 1024;
  int max_send_message_bytes = 16 * 1024 * 1024;
  // On shutdown, in-flight calls get this long to finish before they are cancelled.
  std::chrono::milliseconds drain_deadline{10000};
  // Pipeline parameters (the --config file); sessions may override their segmentation, tsdf and
  // gsm sections.
  Params params;
  // Frames buffered per Ingest stream before the server stops reading it (backpressure).
  int frame_queue = 8;
  // Segments waiting for the database beyond which frame workers put extraction off (the
  // database never stalls frames); 0: nothing is extracted while streaming, all at EndSession.
  int segment_queue = 64;
  // A client that does not read its Ingest stream: at max_pending_events unread events (acks,
  // segment and object events) the server stops taking its frames, so its writes block; after
  // slow_reader_timeout with none of them read, the stream ends with RESOURCE_EXHAUSTED (the
  // session is kept, INTERRUPTED, for EndSession, as after a broken stream).
  int max_pending_events = 64;
  std::chrono::milliseconds slow_reader_timeout{60 * 1000};
  // HTTP/2 keepalive: a client with calls open is pinged after keepalive_time without traffic
  // from it; without an answer within keepalive_timeout its connection is closed (its streams
  // break: a client that vanished without closing its connection). 100 ms .. 24 h, 100 ms .. 1 h.
  std::chrono::milliseconds keepalive_time{60 * 1000};
  std::chrono::milliseconds keepalive_timeout{20 * 1000};
  // A connection without calls is closed after this (0: never; else 100 ms .. 7 days); its client
  // reconnects when it calls again.
  std::chrono::milliseconds max_connection_idle{15 * 60 * 1000};
  // Sessions whose map is in memory at once (streaming, or not ended yet; ~0.1-0.15 GB each for a
  // room at 2 cm). One more Ingest is refused with RESOURCE_EXHAUSTED.
  int max_open_sessions = 16;
  // Ended sessions kept in memory with all their counters (for a repeated EndSession and for
  // ListSessions); the oldest beyond this many are dropped, and the store answers for them (its
  // counters: frames and objects). 0..100000.
  int ended_sessions_kept = 64;
  // Queries run on a pool of their own (server/query_pool.h), off gRPC's threads: its threads
  // and the calls that may wait for one; more are refused with RESOURCE_EXHAUSTED.
  int query_threads = 4;
  int query_queue = 256;
  // A session whose stream closed (or broke) and that gets no EndSession for this long is ended
  // by the server: its map is stored and its segments inserted. 0 = never.
  std::chrono::milliseconds auto_end_after{10 * 60 * 1000};
  // An open session's map is saved this often, so that a crash loses only the frames after the
  // last save (the next start ends the session from it). 0 = never.
  std::chrono::milliseconds save_map_every{60 * 1000};
  // Several servers on one database: this server's name as session lease holder (empty:
  // host:pid:random), and how long a lease lasts without renewal before another server may take
  // the session over (ServiceOptions::lease_ttl).
  std::string server_id;
  std::chrono::milliseconds lease_ttl{15 * 1000};

  // Checks every field; the message names the field and the bad value.
  Status validate() const;
};

// Health-check name of the API service.
inline constexpr char kObjectDatabaseServiceName[] = "objdb.v1.ObjectDatabase";

// Bounds of ServerOptions, documented in the usage text.
inline constexpr int kMinMessageBytes = 4 * 1024;
inline constexpr int kMaxMessageBytes = 1024 * 1024 * 1024;
inline constexpr std::chrono::milliseconds kMaxDrainDeadline{10 * 60 * 1000};
// At a shutdown, how long new calls are answered UNAVAILABLE before gRPC stops taking calls
// (part of the drain deadline).
inline constexpr std::chrono::milliseconds kDrainNotice{200};
inline constexpr int kMaxOpenSessions = 1024;

// A running server. Thread-safe; shutdown() may be called from any thread, any number of times.
class ObjdbServer {
 public:
  // Validates the options, opens the database, binds the address and starts serving (health:
  // SERVING). The database's errors as storage reports them (DATA_LOSS for a corrupt file,
  // FAILED_PRECONDITION for a foreign or newer one); UNAVAILABLE when the address cannot be
  // bound (in use, not a local interface, no permission).
  static StatusOr<std::unique_ptr<ObjdbServer>> start(const ServerOptions& options);

  ~ObjdbServer();  // shuts down (with the drain deadline) if still running
  ObjdbServer(const ObjdbServer&) = delete;
  ObjdbServer& operator=(const ObjdbServer&) = delete;

  const ServerOptions& options() const { return options_; }
  // The bound port: the requested one, or the one chosen by the system for port 0.
  int port() const { return port_; }
  // HOST:PORT actually listened on, e.g. "127.0.0.1:43121".
  std::string address() const;

  // Graceful stop: health turns NOT_SERVING, the listener closes, new calls are refused, calls in
  // flight get options().drain_deadline to finish and are cancelled after it. Blocks until the
  // server has stopped. Later calls return at once.
  void shutdown();
  bool stopped() const;

  // The database the server opened; its writes go through the server's single writer.
  storage::Store& store() { return *store_; }

 private:
  ObjdbServer(ServerOptions options, std::unique_ptr<storage::Store> store,
              std::unique_ptr<server::ObjectDatabaseService> service,
              std::unique_ptr<grpc::Server> server, std::string host, int port);

  const ServerOptions options_;
  std::unique_ptr<storage::Store> store_;  // outlives the services that use it
  // Declared before server_: services must outlive the grpc::Server that calls them.
  std::unique_ptr<server::ObjectDatabaseService> service_;
  std::unique_ptr<grpc::Server> server_;
  const std::string host_;
  const int port_;
  std::mutex mutex_;  // serialises shutdown()
  std::atomic<bool> stopped_{false};
};

}  // namespace objdb
