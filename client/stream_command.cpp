// `objdb stream`: a dataset to an objdb server over gRPC, one Ingest stream per session — the
// on-line counterpart of `objdb ingest`. Frames go out as FLOAT32 depth (metres, exactly what
// the dataset reader produced) with RGB8 colour; a second thread reads the server's acks and
// events while the first writes, so the server's backpressure paces the writer. Then EndSession
// flushes the session's map into the database.
#include <cstdio>
#include <map>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/str_format.h"
#include "client/cli_util.h"
#include "client/commands.h"
#include "client/stream_session.h"
#include "client/remote.h"
#include "core/io/dataset.h"
#include "core/io/io_util.h"
#include "server/proto_convert.h"

namespace objdb {
namespace {

constexpr const char* kCommand = "stream";

constexpr const char* kUsage = R"(usage: objdb stream [--server HOST:PORT] DATASET... [options]

Streams datasets to an objdb server: each dataset (objdb or TUM layout) is one session, named
after its folder (or --session); a folder holding several sessions (the lounge of `objdb sim
--preset lounge`) streams each of them, in name order. A name the database has already is refused
unless --resume or --replace says what to do with it. The server segments every frame, fuses it into the session's
Global Segmentation Map and inserts extracted segments into its object database; this command
shows its acks and events, then ends the session (EndSession), which stores the session's map.

)" OBJDB_CONNECTION_USAGE R"(  --params FILE        per-session parameter overrides as JSON (segmentation, tsdf, gsm sections)
  --session NAME       the session's name (one dataset only; default: its folder's name)
  --resume             continue a session of that name whose stream broke (client killed, network,
                       a bad file): the server says which frames its map holds, the rest are sent;
                       a name not in use starts a new session
  --replace            stream a session of that name again: its segments are withdrawn from the
                       database first (its record is kept as NAME.replaced-TIME)
  --every N            send every N-th frame (default 1)
  --no-end             leave the sessions open (EndSession later, or never)
  --end-timeout S      seconds EndSession may take (default 600)
  -v, --verbose        print every segment and object event
  -h, --help           show this text

exit status: 0 all sessions streamed (rejected frames are reported, not fatal); 1 a call failed;
2 command-line error.
)";

}  // namespace

int runStreamCommand(int argc, char** argv) {
  cli::StreamOptions options;
  std::string params_file, session_name;
  bool session_given = false;
  std::vector<std::string> datasets;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "-h" || a == "--help") {
      std::fputs(kUsage, stdout);
      return 0;
    }
    if (a == "-v" || a == "--verbose") {
      options.verbose = true;
      continue;
    }
    if (a == "--no-end") {
      options.end = false;
      continue;
    }
    if (a == "--resume" || a == "--replace") {
      const auto wanted = a == "--resume" ? v1::SessionHeader::IF_EXISTS_RESUME
                                          : v1::SessionHeader::IF_EXISTS_REPLACE;
      if (options.if_exists != v1::SessionHeader::IF_EXISTS_REFUSE && options.if_exists != wanted) {
        return cli::usageError(kCommand, "--resume and --replace exclude each other", kUsage);
      }
      options.if_exists = wanted;
      continue;
    }
    if (a.rfind("--", 0) != 0) {
      datasets.push_back(a);
      continue;
    }
    if (i + 1 >= argc) return cli::usageError(kCommand, a + " needs a value", kUsage);
    const char* value = argv[++i];
    long long seconds = 0;
    if (cli::takeConnectionFlag(a, value, &options.connection)) {
    } else if (a == "--session") {
      session_name = value;
      session_given = true;
    } else if (a == "--params") {
      params_file = value;
    } else if (a == "--every") {
      if (!cli::parseInt(value, 1, 1000000, &options.every)) {
        return cli::usageError(kCommand, std::string("--every needs a positive integer, got ") + value, kUsage);
      }
    } else if (a == "--end-timeout") {
      if (!cli::parseInt(value, 1, 86400, &seconds)) {
        return cli::usageError(kCommand, std::string("--end-timeout needs 1..86400 seconds, got ") + value, kUsage);
      }
      options.end_timeout_s = double(seconds);
    } else {
      return cli::usageError(kCommand, "unknown option '" + a + "'", kUsage);
    }
  }
  if (datasets.empty()) return cli::usageError(kCommand, "at least one DATASET is required", kUsage);
  if (options.connection.server.empty()) return cli::usageError(kCommand, "--server is empty", kUsage);
  if (!params_file.empty()) {
    auto text = io::internal::readFile(params_file);
    if (!text.ok()) return cli::reportError(kCommand, text.status());
    options.params_json = *text;
  }
  auto sessions = cli::datasetSessions(datasets);
  if (!sessions.ok()) return cli::reportError(kCommand, sessions.status());
  if (session_given) {
    if (sessions->size() != 1) {
      return cli::usageError(kCommand,
                             absl::StrFormat("--session names one session, but the datasets hold "
                                             "%d",
                                             sessions->size()),
                             kUsage);
    }
    (*sessions)[0].first = session_name;  // checked by the server like any name
  }
  auto channel = cli::openChannel(options.connection);
  if (!channel.ok()) return cli::reportError(kCommand, channel.status());
  auto stub = v1::ObjectDatabase::NewStub(*channel);
  for (const auto& [name, path] : *sessions) {
    auto opened = io::openDataset(path);
    if (!opened.ok()) return cli::reportError(kCommand, opened.status());
    if (const int rc = cli::streamSession(*stub, name, **opened, options, kCommand); rc != 0) return rc;
  }
  return 0;
}

}  // namespace objdb
