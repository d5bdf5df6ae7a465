// `objdb eval`: the database's evaluation on the server's own protocol. Starts objdb-server in
// this process on a new database, streams the datasets through it exactly as `objdb stream` does
// (one session each, online inserts, the live scene check, per-extraction replacement), ends the
// sessions, and scores what the database holds: against ground truth where every dataset has it
// (the paper's table and the models each kind ends in and per true object), and for every dataset
// the structure merges (placements on the scenes' dominant planes inside models of two or more
// segments), with the database's time per stage (paper Table II: P, K, D, MR, MV, SV).
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <memory>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "absl/strings/str_format.h"
#include "absl/strings/str_split.h"
#include "client/cli_util.h"
#include "client/commands.h"
#include "client/db_scan.h"
#include "client/db_score.h"
#include "client/eval_completion.h"
#include "client/remote.h"
#include "client/stream_session.h"
#include "core/common/logging.h"
#include "core/io/dataset.h"
#include "server/server.h"
#include "storage/sqlite/sqlite_store.h"

namespace objdb {
namespace {

namespace fs = std::filesystem;

constexpr const char* kCommand = "eval";
constexpr const char* kUsage = R"(usage: objdb eval DATASET... [options]

Runs the datasets through an objdb server started in this process on a new database, as a client
streaming them would (`objdb stream`: one session per dataset, in order; a folder of sessions
gives each), then scores the database:
  - with ground truth (every dataset has instances/ and objects.json): placements, mergeable,
    models, models from >= 2 segments, erroneous merges (kinds differ), structure merges (true
    floor or wall in a model of >= 2), the share of repeated kinds' mergeable segments sharing a
    model with their kind at another place, and the models each kind ends in and per true object;
  - always: the scenes' dominant planes (of the 8 largest planes per session, those holding
    >= 2 % of its surface, their connected faces of >= 1 m²), the placements lying on them, and
    the structure merges (such a placement in a model at >= 2 places);
  - scene completion: each session's scene as GetSceneMesh serves it, measured and completed;
    the surface completion added, the share of it the session's own frames saw through (wrong),
    on another session's measured surface, and with scene.json in every folder (the synthetic
    lounge) on a true surface, with the repeated objects' true surface before and after;
  - the database's time per stage over all inserts (P surface cloud, K keypoints, D descriptors,
    MR matching and registration, MV model check, SV scene check) and each session's wall time.

  --config FILE.json  the server's pipeline parameters (objdb-server --config)
  --db FILE           keep the database in FILE (must not exist); default: a temporary file
  --every N           stream every N-th frame (default 1)
  --structure-ids L   with class labels and no objects.json (labels/ of class ids): the ids that
                      are structure, comma-separated (e.g. NYU40: 1,2,22 for wall, floor,
                      ceiling); the purity and structure leakage count points on them as floor
                      and walls (default: none)
  --scan-every N      look for placements in every N-th frame when scoring (default 1)
  -h, --help          show this text

exit status: 0 evaluated; 1 a dataset, the server or the scoring failed; 2 command-line error.
)";

struct Options {
  std::vector<std::string> datasets;
  std::string config, db;
  long long every = 1, scan_every = 1;
  std::set<int> structure_ids;
};

int parse(int argc, char** argv, Options* o) {
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "-h" || a == "--help") {
      std::fputs(kUsage, stdout);
      return 0;
    }
    if (a.rfind("--", 0) != 0) {
      o->datasets.push_back(a);
      continue;
    }
    if (i + 1 >= argc) return cli::usageError(kCommand, a + " needs a value", kUsage);
    const char* value = argv[++i];
    if (a == "--config") {
      o->config = value;
    } else if (a == "--db") {
      o->db = value;
    } else if (a == "--structure-ids") {
      const std::vector<std::string> ids = absl::StrSplit(value, ',');
      for (const std::string& id : ids) {
        long long n = 0;
        if (!cli::parseInt(id.c_str(), 1, 65535, &n)) {
          return cli::usageError(kCommand,
                                 "--structure-ids needs class ids 1-65535 separated by commas, "
                                 "got " + std::string(value),
                                 kUsage);
        }
        o->structure_ids.insert(int(n));
      }
    } else if (a == "--every" || a == "--scan-every") {
      if (!cli::parseInt(value, 1, 1000000, a == "--every" ? &o->every : &o->scan_every)) {
        return cli::usageError(kCommand, a + " needs a positive integer, got " + value, kUsage);
      }
    } else {
      return cli::usageError(kCommand, "unknown option '" + a + "'", kUsage);
    }
  }
  if (o->datasets.empty()) return cli::usageError(kCommand, "at least one DATASET is required", kUsage);
  return -1;
}

// A temporary folder removed on scope exit.
struct TempFolder {
  fs::path path;
  ~TempFolder() {
    std::error_code ignored;
    if (!path.empty()) fs::remove_all(path, ignored);
  }
};

double secondsSince(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
}

void printTimings(const v1::InsertTimingTotals& t) {
  const double n = double(std::max<uint64_t>(1, t.inserts()));
  const double rest = t.replace_s() + t.prefilter_s() + t.load_s() + t.store_s();
  std::printf("\ndatabase time over %llu inserts (paper Table II), s total and ms per insert:\n",
              (unsigned long long)t.inserts());
  std::printf("%10s %8s %8s %8s %8s %8s %8s %8s\n", "", "P", "K", "D", "MR", "MV", "SV", "rest");
  std::printf("%10s %8.1f %8.1f %8.1f %8.1f %8.1f %8.1f %8.1f   (%.1f s in all)\n", "s", t.cloud_s(),
              t.keypoints_s(), t.descriptors_s(), t.match_register_s(), t.model_verify_s(),
              t.scene_verify_s(), rest, t.total_s());
  std::printf("%10s %8.1f %8.1f %8.1f %8.1f %8.1f %8.1f %8.1f\n", "ms/insert",
              1000 * t.cloud_s() / n, 1000 * t.keypoints_s() / n, 1000 * t.descriptors_s() / n,
              1000 * t.match_register_s() / n, 1000 * t.model_verify_s() / n,
              1000 * t.scene_verify_s() / n, 1000 * rest / n);
}

}  // namespace

int runEvalCommand(int argc, char** argv) {
  Options o;
  if (const int parsed = parse(argc, argv, &o); parsed >= 0) return parsed;
  auto sessions = cli::datasetSessions(o.datasets);
  if (!sessions.ok()) return cli::reportError(kCommand, sessions.status());
  std::map<std::string, std::string> folders;  // session → folder
  std::vector<std::unique_ptr<io::Dataset>> datasets;  // in session order
  bool with_truth = true;
  for (const auto& [name, path] : *sessions) {
    auto opened = io::openDataset(path);  // every folder is readable before anything starts
    if (!opened.ok()) return cli::reportError(kCommand, opened.status());
    datasets.push_back(*std::move(opened));
    if (folders.count(name) != 0) {
      return cli::reportError(kCommand, absl::InvalidArgumentError(absl::StrFormat(
                                            "two datasets are named %s (%s and %s): sessions are "
                                            "named after their folders",
                                            name, folders[name], path.string())));
    }
    folders[name] = path.string();
    with_truth = with_truth && datasets.back()->hasInstances();
  }
  cli::GroundTruth truth;
  if (with_truth) {
    auto read = cli::readGroundTruth(folders, o.structure_ids);
    if (!read.ok()) return cli::reportError(kCommand, read.status());
    truth = *std::move(read);
  }

  ServerOptions server_options;
  auto params = cli::loadParams(o.config);
  if (!params.ok()) return cli::reportError(kCommand, params.status());
  server_options.params = *params;
  server_options.listen_address = "127.0.0.1:0";
  TempFolder temp;
  if (o.db.empty()) {
    std::random_device random;
    temp.path = fs::temp_directory_path() / absl::StrFormat("objdb-eval-%08x", random());
    std::error_code error;
    fs::create_directories(temp.path, error);
    if (error) {
      return cli::reportError(kCommand, absl::UnavailableError(absl::StrFormat(
                                            "cannot create %s: %s", temp.path.string(),
                                            error.message())));
    }
    server_options.db_path = (temp.path / "objects.sqlite").string();
  } else {
    if (fs::exists(o.db)) {
      return cli::reportError(kCommand, absl::AlreadyExistsError(absl::StrFormat(
                                            "%s exists: objdb eval builds a new database", o.db)));
    }
    server_options.db_path = o.db;
  }
  // The server's per-session lines would bury the progress (OBJDB_LOG_LEVEL asks for them).
  if (std::getenv("OBJDB_LOG_LEVEL") == nullptr) setLogLevel("warn");
  auto server = ObjdbServer::start(server_options);
  if (!server.ok()) return cli::reportError(kCommand, server.status());
  cli::Connection connection;
  connection.server = (*server)->address();
  auto channel = cli::openChannel(connection);
  if (!channel.ok()) return cli::reportError(kCommand, channel.status());
  auto stub = v1::ObjectDatabase::NewStub(*channel);
  cli::StreamOptions stream;
  stream.connection = connection;
  stream.every = o.every;
  const auto start = std::chrono::steady_clock::now();
  std::vector<std::pair<std::string, double>> walls;
  for (size_t i = 0; i < sessions->size(); ++i) {
    const std::string& name = (*sessions)[i].first;
    const auto t = std::chrono::steady_clock::now();
    if (const int rc = cli::streamSession(*stub, name, *datasets[i], stream, kCommand); rc != 0) {
      return rc;
    }
    walls.emplace_back(name, secondsSince(t));
  }
  const double wall = secondsSince(start);
  grpc::ClientContext context;
  v1::GetStatsResponse stats;
  const grpc::Status got = stub->GetStats(&context, v1::GetStatsRequest(), &stats);
  if (!got.ok()) return cli::reportRpcError(kCommand, "GetStats", connection.server, got);
  std::vector<cli::SessionMeshes> meshes;  // each session's scene, measured and completed
  for (const auto& [name, path] : *sessions) {
    cli::SessionMeshes m;
    m.session = name;
    for (const bool completed : {false, true}) {
      const grpc::Status fetched = cli::fetchSceneMesh(*stub, name, completed, 0.0,
                                                       completed ? &m.completed : &m.measured);
      if (!fetched.ok()) {
        return cli::reportRpcError(kCommand, "GetSceneMesh", connection.server, fetched);
      }
    }
    meshes.push_back(std::move(m));
  }
  (*server)->shutdown();
  server->reset();

  std::fflush(stdout);  // before the scan's progress on stderr
  storage::SqliteStoreOptions store_options;
  store_options.read_only = true;
  auto store = storage::SqliteStore::open(server_options.db_path, store_options);
  if (!store.ok()) return cli::reportError(kCommand, store.status());
  auto loaded = cli::loadRows(**store, 1, SIZE_MAX);
  if (!loaded.ok()) return cli::reportError(kCommand, loaded.status());
  std::vector<cli::Row> rows = *std::move(loaded);
  if (Status scanned = cli::scanFrames(folders, size_t(o.scan_every), &rows, nullptr);
      !scanned.ok()) {
    return cli::reportError(kCommand, scanned);
  }
  std::printf("\n");
  if (with_truth) {
    std::printf("against ground truth:\n");
    cli::printTruthScore(cli::scoreTruth(rows, truth));
  } else {
    std::printf("no ground truth (not every dataset has instances/ and objects.json)\n");
  }
  std::printf("\ncensus (what a failure looks like: giant objects, structure share):\n");
  cli::printCensusScore(cli::scoreCensus(rows));
  auto structure = cli::scoreStructure(**store, rows);
  if (!structure.ok()) return cli::reportError(kCommand, structure.status());
  std::printf("\nagainst the scenes' dominant planes:\n");
  cli::printStructureScore(*structure);
  std::printf("\nmodel-to-scene checks %llu, candidates rejected by them %llu, poses without a "
              "scene %llu; merges onto a placement of their own session %llu\n",
              (unsigned long long)stats.scene_checks(),
              (unsigned long long)stats.candidates_rejected_by_scene(),
              (unsigned long long)stats.poses_without_scene(),
              (unsigned long long)stats.merges_same_place());
  if (Status scored = cli::printCompletionScore(meshes, folders); !scored.ok()) {
    return cli::reportError(kCommand, scored);
  }
  printTimings(stats.insert_timings());
  for (const auto& [name, seconds] : walls) {
    std::printf("session %s streamed and ended in %.1f s\n", name.c_str(), seconds);
  }
  std::printf("all sessions: %.1f s\n", wall);
  if (!o.db.empty()) std::printf("database kept in %s\n", o.db.c_str());
  return 0;
}

}  // namespace objdb
