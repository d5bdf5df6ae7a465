// objdb-server: command line, configuration check, serving until SIGINT/SIGTERM.
#include <cstdio>
#include <string>

#include "absl/strings/numbers.h"
#include "absl/strings/str_format.h"
#include "core/common/logging.h"
#include "core/common/params_io.h"
#include "server/server.h"
#include "server/shutdown_signals.h"

namespace {

constexpr int kExitUsage = 2;
constexpr int kExitCannotStart = 1;

std::string usage() {
  const objdb::ServerOptions defaults;
  return absl::StrFormat(
      R"(usage: objdb-server [options]

Serves the objdb object database over gRPC (service objdb.v1.ObjectDatabase) together with the
standard health service (grpc.health.v1.Health): clients stream sessions in (Ingest, e.g.
`objdb stream DATASET`) and query sessions, objects and meshes (`objdb remote`); see
docs/server.md. SIGINT or SIGTERM drains calls in flight and stops the server; a second signal
exits at once. Sessions not ended by then are ended by the server (their maps are stored).

options:
  --listen HOST:PORT      address to listen on (default %s); port 0 picks a free
                          port. The address is logged as "listening on HOST:PORT".
  --token-file FILE       require "authorization: Bearer <token>" on every objdb.v1 call, the
                          token being FILE's content (16..4096 printable characters, e.g.
                          `openssl rand -hex 32 > FILE`); others get UNAUTHENTICATED. Health
                          checks need no token. The token is never logged.
  --tls-cert FILE         serve TLS with this PEM certificate chain ...
  --tls-key FILE          ... and its PEM private key
  --tls-client-ca FILE    require client certificates signed by this PEM CA (mutual TLS)
  --allow-remote          accept a non-loopback --listen address (such as 0.0.0.0:50051)
                          without TLS + token or client certificates. Without them anyone who
                          can reach the port can read and write the database.
  --db PATH|URI           SQLite database file, created if missing (default %s), or a
                          PostgreSQL database as a libpq URI (postgresql://USER@HOST/DB;
                          password from ~/.pgpass or PGPASSWORD, TLS per sslmode; several
                          servers may share one, docs/storage.md); a corrupt file, an
                          unreachable server, another application's database or a newer
                          schema refuses the start, and the database is left untouched
  --config FILE           pipeline parameters as JSON, e.g. {"tsdf": {"voxel_size_m": 0.01}};
                          checked at startup: unknown keys and bad values refuse the start
  --print-config          print the effective parameters (defaults + --config) as JSON, exit
  --max-message-mib N     largest gRPC message received or sent, MiB, 1..1024 (default %d)
  --drain-deadline-ms N   on shutdown, time calls in flight get to finish (default %d)
  --max-sessions N        sessions whose map is in memory at once (streaming, or not ended yet),
                          1..%d (default %d); one more Ingest gets RESOURCE_EXHAUSTED
  --query-threads N       threads that run the queries (ListSessions, ListObjects, GetObject,
                          GetStats, Match, ObjectsInRegion, SessionChanges), off gRPC's
                          threads, 1..64 (default 4)
  --query-queue N         queries that may wait for one of them, 1..100000 (default 256); one
                          more is refused at once with RESOURCE_EXHAUSTED ("the server is busy")
  --auto-end-s N          end a session whose stream closed or broke after N seconds without
                          EndSession (its map is stored); 0 = never (default 600)
  --save-map-s S          save each open session's map every S seconds (and, unless
                          --auto-end-s is 0, once more a few seconds after its stream went), so
                          that a crash loses only the frames after the last save: the next
                          start ends the session from it; 0 = never (default 60)
  --server-id NAME        this server's name as holder of session leases, unique among the
                          servers on one database (default host:pid:random)
  --lease-s S             a session's lease lasts S seconds without renewal (renewed every S/3);
                          when its server dies, another server on the database takes the
                          session over after that, 0.1..3600 (default 15)
  --slow-reader-s N       end an Ingest stream whose client has read none of its events for N
                          seconds while they wait (at 64 waiting acks and events its frames
                          wait too), with RESOURCE_EXHAUSTED; the session is kept
                          (interrupted) for EndSession, 1..86400 (default 60)
  --keepalive-s S         ping a client with calls open after S seconds without traffic from it
                          (default 60), and close its connection when no answer comes within
                          --keepalive-timeout-s S (default 20): a client that vanished without
                          closing its connection (powered off, suspended) has its streams
                          broken, and its sessions kept (interrupted) for EndSession
  --max-connection-idle-s S
                          close a connection without calls after S seconds (default 900; 0 =
                          never); its client reconnects when it calls again
  --log-level LEVEL       trace, debug, info, warn, error, critical or off (default info)
  -h, --help              show this text and exit

exit status: 0 after a clean shutdown, 1 if the server cannot start (bad configuration, address
in use), 2 on a command-line error.
)",
      defaults.listen_address, defaults.db_path, defaults.max_receive_message_bytes >> 20,
      static_cast<int>(defaults.drain_deadline.count()), objdb::kMaxOpenSessions,
      defaults.max_open_sessions);
}

struct CommandLine {
  objdb::ServerOptions options;
  std::string config_path;
  std::string log_level = "info";
  bool help = false;
  bool print_config = false;
};

// Fills `cli` from argv; on a usage error returns false with `error` set. Accepts "--flag value"
// and "--flag=value".
bool parseCommandLine(int argc, char** argv, CommandLine* cli, std::string* error) {
  for (int i = 1; i < argc; ++i) {
    std::string arg = argv[i];
    std::string value;
    bool has_inline_value = false;
    if (const size_t eq = arg.find('='); arg.rfind("--", 0) == 0 && eq != std::string::npos) {
      value = arg.substr(eq + 1);
      arg = arg.substr(0, eq);
      has_inline_value = true;
    }
    auto take_value = [&](std::string* out) {
      if (has_inline_value) {
        *out = value;
        return true;
      }
      if (i + 1 >= argc) {
        *error = absl::StrFormat("%s needs a value", arg);
        return false;
      }
      *out = argv[++i];
      return true;
    };
    auto take_int = [&](int min, int max, int* out) {
      std::string text;
      if (!take_value(&text)) return false;
      if (!absl::SimpleAtoi(text, out) || *out < min || *out > max) {
        *error =
            absl::StrFormat("%s must be an integer in [%d, %d], got \"%s\"", arg, min, max, text);
        return false;
      }
      return true;
    };
    // Seconds as a number in [min, max] (or 0 when zero_means_never), to milliseconds.
    auto take_seconds = [&](double min, double max, bool zero_means_never,
                            std::chrono::milliseconds* out) {
      std::string text;
      if (!take_value(&text)) return false;
      double seconds = 0.0;
      if (!absl::SimpleAtod(text, &seconds) ||
          !((seconds >= min && seconds <= max) || (zero_means_never && seconds == 0.0))) {
        *error = absl::StrFormat("%s must be %sa number of seconds in [%g, %g], got \"%s\"", arg,
                                 zero_means_never ? "0 (never) or " : "", min, max, text);
        return false;
      }
      *out = std::chrono::milliseconds(static_cast<int64_t>(seconds * 1000.0 + 0.5));
      return true;
    };
    auto no_value = [&]() {
      if (has_inline_value) *error = absl::StrFormat("%s takes no value", arg);
      return !has_inline_value;
    };

    if (arg == "-h" || arg == "--help") {
      if (!no_value()) return false;
      cli->help = true;
    } else if (arg == "--listen") {
      if (!take_value(&cli->options.listen_address)) return false;
    } else if (arg == "--allow-remote") {
      if (!no_value()) return false;
      cli->options.allow_remote = true;
    } else if (arg == "--token-file") {
      if (!take_value(&cli->options.token_file)) return false;
    } else if (arg == "--tls-cert") {
      if (!take_value(&cli->options.tls_cert_file)) return false;
    } else if (arg == "--tls-key") {
      if (!take_value(&cli->options.tls_key_file)) return false;
    } else if (arg == "--tls-client-ca") {
      if (!take_value(&cli->options.tls_client_ca_file)) return false;
    } else if (arg == "--db") {
      if (!take_value(&cli->options.db_path)) return false;
    } else if (arg == "--config") {
      if (!take_value(&cli->config_path)) return false;
    } else if (arg == "--print-config") {
      if (!no_value()) return false;
      cli->print_config = true;
    } else if (arg == "--max-message-mib") {
      int mib = 0;
      if (!take_int(1, objdb::kMaxMessageBytes >> 20, &mib)) return false;
      cli->options.max_receive_message_bytes = mib << 20;
      cli->options.max_send_message_bytes = mib << 20;
    } else if (arg == "--drain-deadline-ms") {
      int ms = 0;
      if (!take_int(0, static_cast<int>(objdb::kMaxDrainDeadline.count()), &ms)) return false;
      cli->options.drain_deadline = std::chrono::milliseconds(ms);
    } else if (arg == "--auto-end-s") {
      int seconds = 0;
      if (!take_int(0, 7 * 24 * 3600, &seconds)) return false;
      cli->options.auto_end_after = std::chrono::seconds(seconds);
    } else if (arg == "--save-map-s") {
      if (!take_seconds(0.001, 24 * 3600.0, true, &cli->options.save_map_every)) return false;
    } else if (arg == "--server-id") {
      if (!take_value(&cli->options.server_id)) return false;
    } else if (arg == "--lease-s") {
      if (!take_seconds(0.1, 3600.0, false, &cli->options.lease_ttl)) return false;
    } else if (arg == "--keepalive-s") {
      if (!take_seconds(0.1, 24 * 3600.0, false, &cli->options.keepalive_time)) return false;
    } else if (arg == "--keepalive-timeout-s") {
      if (!take_seconds(0.1, 3600.0, false, &cli->options.keepalive_timeout)) return false;
    } else if (arg == "--max-connection-idle-s") {
      if (!take_seconds(0.1, 7 * 24 * 3600.0, true, &cli->options.max_connection_idle)) {
        return false;
      }
    } else if (arg == "--slow-reader-s") {
      int seconds = 0;
      if (!take_int(1, 24 * 3600, &seconds)) return false;
      cli->options.slow_reader_timeout = std::chrono::seconds(seconds);
    } else if (arg == "--query-threads") {
      if (!take_int(1, 64, &cli->options.query_threads)) return false;
    } else if (arg == "--query-queue") {
      if (!take_int(1, 100000, &cli->options.query_queue)) return false;
    } else if (arg == "--max-sessions") {
      if (!take_int(1, objdb::kMaxOpenSessions, &cli->options.max_open_sessions)) return false;
    } else if (arg == "--log-level") {
      if (!take_value(&cli->log_level)) return false;
    } else {
      *error = absl::StrFormat("unknown option \"%s\"", argv[i]);
      return false;
    }
  }
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  // Before anything can start a thread: every thread inherits the blocked mask, so SIGINT and
  // SIGTERM only ever reach the watcher's sigwait().
  if (!objdb::blockShutdownSignals()) {
    std::fprintf(stderr, "objdb-server: cannot block SIGINT/SIGTERM\n");
    return kExitCannotStart;
  }

  CommandLine cli;
  std::string error;
  if (!parseCommandLine(argc, argv, &cli, &error)) {
    std::fprintf(stderr, "objdb-server: %s\n\n%s", error.c_str(), usage().c_str());
    return kExitUsage;
  }
  if (cli.help) {
    std::fputs(usage().c_str(), stdout);
    return 0;
  }
  if (!objdb::setLogLevel(cli.log_level)) {
    std::fprintf(stderr,
                 "objdb-server: unknown --log-level \"%s\" (use trace, debug, info, warn, error, "
                 "critical or off)\n",
                 cli.log_level.c_str());
    return kExitUsage;
  }

  if (!cli.config_path.empty()) {
    objdb::StatusOr<objdb::Params> params = objdb::loadParamsFile(cli.config_path);
    if (!params.ok()) {
      std::fprintf(stderr, "objdb-server: bad --config: %s\n",
                   std::string(params.status().message()).c_str());
      return kExitCannotStart;
    }
    cli.options.params = *std::move(params);
  }
  if (cli.print_config) {
    std::fputs((objdb::paramsToJson(cli.options.params) + "\n").c_str(), stdout);
    return 0;
  }
  if (const objdb::Status valid = cli.options.validate(); !valid.ok()) {
    std::fprintf(stderr, "objdb-server: %s\n", std::string(valid.message()).c_str());
    return kExitCannotStart;
  }

  objdb::ShutdownSignalWatcher signals;
  objdb::StatusOr<std::unique_ptr<objdb::ObjdbServer>> server =
      objdb::ObjdbServer::start(cli.options);
  if (!server.ok()) {
    std::fprintf(stderr, "objdb-server: %s\n", std::string(server.status().message()).c_str());
    return kExitCannotStart;
  }
  signals.waitForRequest();
  (*server)->shutdown();
  return 0;
}
