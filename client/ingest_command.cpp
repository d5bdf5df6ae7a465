// `objdb ingest`: the whole pipeline offline into a database file — every session of the given
// datasets is segmented, fused into its Global Segmentation Map, its raw segments are inserted
// into the object database (Algorithm 1) as they are extracted, and its scene map is stored; the
// database is the SQLite file, so a second run adds sessions to what the first one learned.
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "client/cli_util.h"
#include "client/commands.h"
#include "client/frame_loop.h"
#include "core/common/params_io.h"
#include "core/database/object_database.h"
#include "core/io/dataset.h"
#include "storage/model_settings.h"
#include "storage/sqlite/sqlite_store.h"

namespace objdb {
namespace {

constexpr const char* kUsage = R"(usage: objdb ingest --db FILE.sqlite DATASET... [options]

Runs the pipeline offline into a database file: each dataset (objdb or TUM layout) is one
session, named after its folder; a folder holding several sessions (such as the lounge written by
`objdb sim --preset lounge`) adds each of them, in name order. Frames are segmented and fused into
the session's Global Segmentation Map; every extracted raw segment goes into the object database
(matched, verified and merged with the models already stored); at the end of a session its scene
map is stored. The file is created when missing; sessions already in it are refused.

  --db FILE        database file (SQLite)
  --config FILE    parameters as JSON (all sections apply)
  --every N        use every N-th frame (default 1)
  --threads N      TSDF integration and candidate registration threads (default 2)
  --synchronous S  FULL (default: commits survive power loss) or NORMAL (survive crashes)
)";

constexpr const char* kCommand = "ingest";

}  // namespace

int runIngestCommand(int argc, char** argv) {
  std::string db_path, config, synchronous = "FULL";
  long long every = 1, threads = 2;
  std::vector<std::string> datasets;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "-h" || a == "--help") {
      std::fputs(kUsage, stdout);
      return 0;
    }
    if (a.rfind("--", 0) != 0) {
      datasets.push_back(a);
      continue;
    }
    if (i + 1 >= argc) return cli::usageError(kCommand, a + " needs a value", kUsage);
    const char* value = argv[++i];
    if (a == "--db") {
      db_path = value;
    } else if (a == "--config") {
      config = value;
    } else if (a == "--synchronous") {
      synchronous = value;
    } else if (a == "--every") {
      if (!cli::parseInt(value, 1, 1000000, &every)) {
        return cli::usageError(kCommand, std::string("--every needs a positive integer, got ") + value, kUsage);
      }
    } else if (a == "--threads") {
      if (!cli::parseInt(value, 1, 64, &threads)) {
        return cli::usageError(kCommand, std::string("--threads needs 1..64, got ") + value, kUsage);
      }
    } else {
      return cli::usageError(kCommand, "unknown option '" + a + "'", kUsage);
    }
  }
  if (db_path.empty() || datasets.empty()) {
    return cli::usageError(kCommand, "--db FILE and at least one DATASET are required", kUsage);
  }
  auto loaded = cli::loadParams(config);
  if (!loaded.ok()) return cli::reportError(kCommand, loaded.status());
  Params params = *loaded;
  params.database.threads = int(threads);
  auto sessions = cli::datasetSessions(datasets);
  if (!sessions.ok()) return cli::reportError(kCommand, sessions.status());

  storage::SqliteStoreOptions options;
  options.synchronous = synchronous;
  auto store = storage::SqliteStore::open(db_path, options);
  if (!store.ok()) return cli::reportError(kCommand, store.status());
  // Refuse sessions already stored before doing any work.
  auto known = (*store)->sessions();
  if (!known.ok()) return cli::reportError(kCommand, known.status());
  for (const auto& [name, path] : *sessions) {
    for (const auto& s : *known) {
      if (s.name == name) {
        return cli::reportError(kCommand, absl::AlreadyExistsError(absl::StrFormat(
                                              "session %s is already in %s (state %s); rename "
                                              "the dataset folder to add it again",
                                              name, db_path, storage::sessionStateName(s.state))));
      }
    }
  }
  if (Status same = storage::checkModelSettings(*known, params); !same.ok()) {
    return cli::reportError(kCommand, same);
  }
  auto db = database::ObjectDatabase::create(params, store->get());
  if (!db.ok()) return cli::reportError(kCommand, db.status());

  for (const auto& [name, path] : *sessions) {
    auto opened = io::openDataset(path);
    if (!opened.ok()) return cli::reportError(kCommand, opened.status());
    const io::Dataset& ds = **opened;
    auto segmenter = segmentation::DepthSegmenter::create(params.segmentation, ds.intrinsics());
    if (!segmenter.ok()) return cli::reportError(kCommand, segmenter.status());
    auto map = gsm::Gsm::create(params.tsdf, params.gsm, ds.intrinsics(), int(threads));
    if (!map.ok()) return cli::reportError(kCommand, map.status());
    map->setNoiseModel(params.model);
    storage::SessionInfo info;
    info.name = name;
    info.intrinsics_json = storage::intrinsicsJson(ds.intrinsics());
    info.params_json = paramsToJson(params);  // effective parameters (checkModelSettings)
    if (auto begun = (*store)->beginSession(info); !begun.ok()) {
      return cli::reportError(kCommand, begun.status());
    }
    std::printf("session %s: %zu frames from %s\n", name.c_str(), ds.size(), path.c_str());
    size_t inserted = 0, merged = 0, joined = 0, skipped = 0, withdrawn_count = 0;
    auto insert = [&](std::vector<gsm::RawSegment> segments,
                      std::vector<gsm::Label> withdrawn) -> Status {
      for (const gsm::Label label : withdrawn) {  // before the survivors' new segments
        OBJDB_ASSIGN_OR_RETURN(const auto withdrawal, (*db)->withdrawSegment(name, label));
        withdrawn_count += withdrawal.model_id != 0 ? 1 : 0;
      }
      if (segments.empty()) return absl::OkStatus();
      // The session's scene is stored at its end: until then its poses are verified against the
      // map as it is now (as the server does).
      const auto scene = std::make_shared<const tsdf::TsdfLayer>(map->tsdf().snapshot());
      const database::LiveScenes live =
          [&](const std::string& session) -> std::shared_ptr<const tsdf::TsdfLayer> {
        return session == name ? scene : nullptr;
      };
      for (const auto& segment : segments) {
        auto report = (*db)->insertSegment(name, segment, live);
        if (!report.ok()) return report.status();  // every error ends the run
        if (report->unusable) {  // no surface at the mesh weight: stored, held by no model
          ++skipped;
          continue;
        }
        ++inserted;
        merged += report->merged ? 1 : 0;
        joined += report->absorbed().size();
      }
      return absl::OkStatus();
    };
    auto looped = cli::segmentAndFuse(ds, &*segmenter, &*map, size_t(every), kCommand,
                                      "  segmenting, fusing, inserting", insert);
    if (!looped.ok()) {
      (void)(*store)->finishSession(name, storage::SessionState::kInterrupted, 0);
      return cli::reportError(kCommand, looped.status());
    }
    const Status scene =
        (*store)->putScene(name, std::make_shared<const tsdf::TsdfLayer>(map->tsdf().snapshot()),
                           std::make_shared<const gsm::LabelBlocks>(map->mainLabelBlocks()));
    if (!scene.ok()) return cli::reportError(kCommand, scene);
    const Status finished =
        (*store)->finishSession(name, storage::SessionState::kEnded, int64_t(looped->used));
    if (!finished.ok()) return cli::reportError(kCommand, finished);
    const auto ids = (*store)->modelIds();
    std::printf("  %zu frames (%zu skipped), %zu raw segments inserted (%zu merged into earlier "
                "models, %zu without surface skipped, %zu withdrawn); %zu models merged into "
                "others; %zu models in the database\n",
                looped->used, looped->rejected, inserted, merged, skipped, withdrawn_count, joined,
                ids.ok() ? ids->size() : size_t(0));
  }
  if (Status s = (*store)->checkpoint(); !s.ok()) return cli::reportError(kCommand, s);
  std::printf("database: %s\n", db_path.c_str());
  return 0;
}

}  // namespace objdb
