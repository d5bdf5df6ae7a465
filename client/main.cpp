// objdb: command-line client of the objdb server. Dispatches to the subcommands in commands.h.
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include "client/commands.h"
#include "core/common/logging.h"

namespace {

constexpr const char* kUsage = R"(usage: objdb <command> [options]

Command-line client of objdb, the incremental 3D object database.

commands:
  health   ask a server whether it is serving (grpc.health.v1 Check)
  sim      render synthetic RGB-D datasets with ground truth (presets or scene files)
  info     describe dataset folders (objdb or TUM layout): frames, camera, objects
  fuse     integrate a dataset into a TSDF volume and write its surface as a PLY mesh
  gsm      segment + fuse a dataset into a Global Segmentation Map; label-coloured mesh, segments
  segment  segment one dataset frame and write its steps as PNGs (depth, normals, labels, ...)
  ingest   run datasets through segmentation, GSM and the object database into a SQLite file
  db       check, describe and export from a database file (read-only)
  stream   stream datasets to an objdb server (one Ingest stream per session, then EndSession)
  remote   ask an objdb server: stats, sessions, objects, an object's mesh, a scene's mesh
  report   merges: a PNG sheet of every multi-segment model over the camera images; truth:
           a database scored against the datasets' ground truth
  eval     run datasets through an in-process server on a new database and score it
  web      serve a read-only web viewer of a server's database (sessions, objects, scenes)
  help     show this text

Run "objdb <command> --help" for the options of a command.

environment:
  OBJDB_LOG_LEVEL  trace, debug, info, warn, error, critical or off: the log level of the
                   pipeline's messages (default info; eval's in-process server: warn)
)";

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "objdb: no command given\n\n%s", kUsage);
    return 2;
  }
  const std::string command = argv[1];
  if (const char* level = std::getenv("OBJDB_LOG_LEVEL"); level != nullptr && *level != '\0') {
    if (!objdb::setLogLevel(level)) {
      std::fprintf(stderr, "objdb: unknown OBJDB_LOG_LEVEL \"%s\" (use trace, debug, info, warn, "
                   "error, critical or off)\n", level);
      return 2;
    }
  }
  if (command == "help" || command == "--help" || command == "-h") {
    std::fputs(kUsage, stdout);
    return 0;
  }
  if (command == "health") return objdb::runHealthCommand(argc - 1, argv + 1);
  if (command == "sim") return objdb::runSimCommand(argc - 1, argv + 1);
  if (command == "info") return objdb::runInfoCommand(argc - 1, argv + 1);
  if (command == "segment") return objdb::runSegmentCommand(argc - 1, argv + 1);
  if (command == "fuse") return objdb::runFuseCommand(argc - 1, argv + 1);
  if (command == "gsm") return objdb::runGsmCommand(argc - 1, argv + 1);
  if (command == "db") return objdb::runDbCommand(argc - 1, argv + 1);
  if (command == "ingest") return objdb::runIngestCommand(argc - 1, argv + 1);
  if (command == "stream") return objdb::runStreamCommand(argc - 1, argv + 1);
  if (command == "remote") return objdb::runRemoteCommand(argc - 1, argv + 1);
  if (command == "web") return objdb::runWebCommand(argc - 1, argv + 1);
  if (command == "report") return objdb::runReportCommand(argc - 1, argv + 1);
  if (command == "eval") return objdb::runEvalCommand(argc - 1, argv + 1);
  std::fprintf(stderr, "objdb: unknown command \"%s\"\n\n%s", command.c_str(), kUsage);
  return 2;
}
