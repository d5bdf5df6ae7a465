// `objdb web`: a read-only web viewer of an objdb server's database (client/web/): an HTTP
// server that is a client of the gRPC API, with pages for sessions, objects and scenes.
#include <cstdio>
#include <filesystem>
#include <string>
#include <thread>

#include "client/cli_util.h"
#include "client/commands.h"
#include "client/remote.h"
#include "client/web/web_server.h"
#include "core/common/logging.h"
#include "server/shutdown_signals.h"

namespace objdb {
namespace {

constexpr const char* kCommand = "web";

constexpr const char* kUsage = R"(usage: objdb web [--server HOST:PORT] [--listen HOST:PORT] [options]

Serves a read-only web viewer of an objdb server's database: sessions, a gallery of the objects
(thumbnails drawn here), each object in 3D with its placements and merge evidence, and each
session's scene, raw or completed, with its merged models highlighted. It is a client of the
server's gRPC API (docs/web.md); SIGINT or SIGTERM stops it.

)" OBJDB_CONNECTION_USAGE R"(  --listen HOST:PORT   where to serve HTTP (default 127.0.0.1:8080; port 0 picks a free port,
                       printed as "serving on URL")
  --web-token-file F   require the token in F from browsers (open /login?token=... once) and
                       other HTTP clients ("Authorization: Bearer ...")
  --https-cert FILE    serve HTTPS with this PEM certificate chain ...
  --https-key FILE     ... and its PEM private key
  --allow-remote       serve on a non-loopback address without HTTPS and a web token (anyone
                       who can reach the port can read the database)
  --pages DIR          the web pages (default: share/objdb/web beside the binary)
  --three DIR          three.js (default /usr/share/javascript/three, Debian's libjs-three)
  --dataset SESSION=DIR  the dataset folder of a session (repeatable): the object page then
                       shows the model's merge-sheet row, its placements over the frames that
                       see them best (as `objdb report merges`)
  --timeout S          deadline of each call to the server, seconds (default 30; scenes 600)
  -h, --help           show this text

A non-loopback --listen address is refused unless HTTPS and --web-token-file are given, or
--allow-remote. exit status: 0 stopped by a signal; 1 cannot serve; 2 command-line error.
)";

std::string defaultPages() {
  std::error_code ec;
  const std::filesystem::path exe = std::filesystem::read_symlink("/proc/self/exe", ec);
  if (ec) return "share/objdb/web";
  return (exe.parent_path().parent_path() / "share" / "objdb" / "web").string();
}

}  // namespace

int runWebCommand(int argc, char** argv) {
  blockShutdownSignals();  // before gRPC starts threads: signals go to the watcher only
  cli::Connection connection;
  web::WebOptions options;
  options.pages_dir = defaultPages();
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "-h" || a == "--help") {
      std::fputs(kUsage, stdout);
      return 0;
    }
    if (a == "--allow-remote") {
      options.allow_remote = true;
      continue;
    }
    if (i + 1 >= argc) return cli::usageError(kCommand, a + " needs a value", kUsage);
    const std::string value = argv[++i];
    long long seconds = 0;
    if (cli::takeConnectionFlag(a, value, &connection)) {
    } else if (a == "--listen") {
      options.listen = value;
    } else if (a == "--web-token-file") {
      options.token_file = value;
    } else if (a == "--https-cert") {
      options.https_cert = value;
    } else if (a == "--https-key") {
      options.https_key = value;
    } else if (a == "--pages") {
      options.pages_dir = value;
    } else if (a == "--dataset") {
      const size_t eq = value.find('=');
      if (eq == std::string::npos || eq == 0 || eq + 1 == value.size()) {
        return cli::usageError(kCommand, "--dataset needs SESSION=DIR, got " + value, kUsage);
      }
      options.datasets[value.substr(0, eq)] = value.substr(eq + 1);
    } else if (a == "--three") {
      options.three_dir = value;
    } else if (a == "--timeout") {
      if (!cli::parseInt(value.c_str(), 1, 86400, &seconds)) {
        return cli::usageError(kCommand, "--timeout needs 1..86400 seconds, got " + value, kUsage);
      }
      options.call_timeout_s = double(seconds);
    } else {
      return cli::usageError(kCommand, "unknown option '" + a + "'", kUsage);
    }
  }
  if (connection.server.empty()) return cli::usageError(kCommand, "--server is empty", kUsage);
  auto channel = cli::openChannel(connection);
  if (!channel.ok()) return cli::reportError(kCommand, channel.status());
  auto server = web::WebServer::start(*channel, options);
  if (!server.ok()) return cli::reportError(kCommand, server.status());
  ShutdownSignalWatcher signals;
  std::thread serving([&] { (*server)->serve(); });
  std::printf("objdb web: serving on %s (objdb server %s)\n", (*server)->url().c_str(),
              connection.server.c_str());
  std::fflush(stdout);
  const int signal = signals.waitForRequest();
  logger("web")->info("signal {}: stopping", signal);
  (*server)->stop();
  serving.join();
  return 0;
}

}  // namespace objdb
