// insert_bench: the scale target — one chair-sized segment inserted into a database of N
// models (N = 1,000, 3,000, 10,000, 30,000): median < 200 ms and p99 < 1 s, on SQLite and on
// PostgreSQL. Each insert is the server's: ObjectDatabase::insertSegment (Algorithm 1: the model
// built, the prefilter's candidates registered, verified model to model and against the scene at
// every pose, merged or stored alone) on the store storage::openStore opens for the target, with
// the server's default Params. For each N (ascending) the store is filled up to N models, going on
// from the previous N (store->addModel, not insertSegment: copies of 8 chair models of
// bench/chair_model.h at 1 cm with 500 described keypoints, each with its raw segment), the
// database opened on it (its prefilter loaded; every copy but the first of each kind has its
// descriptors jittered, see jitter()), then --inserts chairs inserted one at a time.
// Prints per N the fill and open seconds, insert latency (median, p90, p99, max, mean; with 50
// inserts p99 is the second slowest), candidates per insert and the share merged, then the mean
// time of each step, and the wall time of 4 Match queries (ObjectDatabase::match, nothing
// written) of chairs not inserted. Not a test: figures vary with the machine.
//
//   build/bin/insert_bench [--models 1000,3000,10000] [--inserts 50] [--dir /tmp]
//   build/bin/insert_bench --db postgresql://USER@HOST/EMPTY_DB [--models 1000,3000,10000,30000]
//   build/bin/insert_bench --epsilon 2 --recall on   (database.prefilter_epsilon, and its recall
//                                                     against the exhaustive vote per insert)
//   build/bin/insert_bench --shortlist 0 --recall on (database.shortlist; with --recall the rank
//                                                     of every accepted model by global similarity)
#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "absl/strings/numbers.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_split.h"
#include "bench/chair_model.h"
#include "bench/prefilter_recall.h"
#include "core/common/logging.h"
#include "core/common/params.h"
#include "core/common/transform.h"
#include "core/database/object_database.h"
#include "core/gsm/gsm.h"
#include "core/tsdf/tsdf_layer.h"
#include "storage/open_store.h"

namespace objdb {
namespace {

using Clock = std::chrono::steady_clock;
double secondsSince(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

constexpr int kKinds = 8;
constexpr int kMatches = 4;  // Match queries per N
constexpr float kObservationDepthM = 1.5f;
const char* const kFillSession = "fill";
const char* const kBenchSession = "bench";

// Scenes. Every pose of a candidate and of the segment is verified against its session's scene
// map, and a pose without one rejects the candidate there, unchecked (scenes_missing): without
// scenes every insert would be stored alone, at less than its true cost. So the sessions have
// scenes as on the server. "fill" is an ended session: its scene is stored (putScene), as
// EndSession stores it, and holds the first copy of each kind at its place; the other copies
// stand elsewhere in that session's world, where the map shows nothing (a map of every copy would
// take megabytes per model), so a copy of the segment's kind passes registration and the model
// check and fails at the scene check: each such candidate costs its whole evaluation, and a
// segment can merge only into a first copy or into an earlier bench chair of its kind. "bench" is
// the open session the segments come from: its map (the chairs inserted so far, at their poses)
// is passed as LiveScenes, as the server passes a live session's GSM map.

// A kind of chair the fill copies: its model (model frame = its raw segment's frame) and that raw
// segment's grid, shared by every copy.
struct Kind {
  model::ObjectModel model;
  std::shared_ptr<const tsdf::TsdfLayer> grid;
};

// Where fill copy `i` stands in session "fill": the first of each kind on a row the scene map
// shows, 2 m apart; the others on a lattice beyond it. Translations by whole voxels, as the GSM's
// segment frames are.
Transform fillPose(int64_t i) {
  if (i < kKinds) return poseFromXyzYaw({2.0 * double(i), 0.0, 0.0}, 0.0);
  return poseFromXyzYaw({2.0 * double(i % 100), 10.0 + 2.0 * double(i / 100), 0.0}, 0.0);
}

// A copy's descriptors moved by N(0, kJitter) per bin (FPFH bins hold 0-100; the jitter moves a
// descriptor by about 3, its similarity to the original drops by about 0.02, t_sim is 0.4): near
// its kind's, no longer identical. Exact copies would tie for every nearest neighbour, which no
// database holds (copies of one object merge into one model with many poses), and which turns
// any kd-tree search into a scan of the ties.
constexpr float kJitter = 0.5f;
void jitter(std::vector<model::Fpfh>* descriptors, uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> noise(0.0f, kJitter);
  for (auto& d : *descriptors) {
    for (float& x : d) x = std::max(0.0f, x + noise(rng));
  }
}

// Adds copies of the kinds (one raw segment and one model, a transaction each) until the store
// holds `target` active models; `next` numbers the copies across calls (label = number + 1).
Status fill(storage::Store* store, const std::vector<Kind>& kinds, size_t active, size_t target,
            int64_t* next) {
  const size_t to_add = target > active ? target - active : 0;
  const auto t = Clock::now();
  for (size_t added = 0; added < to_add; ++added, ++*next) {
    const int64_t i = *next;
    const Kind& kind = kinds[size_t(i) % kinds.size()];
    const uint32_t label = uint32_t(i + 1);
    const Transform T_world_segment = fillPose(i);
    // The raw segment first: the model's observation refers to it, and a merge rebuilds the
    // model from it.
    database::RawSegmentRecord record;
    record.key = {kFillSession, label};
    record.T_world_segment = T_world_segment;
    record.grid = kind.grid;
    record.voxels = kind.model.surface_voxels;
    record.extraction_frame = i;
    record.observation_depth_m = kObservationDepthM;
    record.parts = {label};
    record.voxel_parts.assign(record.voxels.size(), label);
    OBJDB_RETURN_IF_ERROR(store->putRawSegment(record));
    model::ObjectModel copy = model::cloneModel(kind.model);
    if (i >= kKinds) jitter(&copy.descriptors, uint32_t(i));
    copy.observations = {{kFillSession, label, T_world_segment, Transform::Identity()}};
    OBJDB_RETURN_IF_ERROR(store->addModel(std::move(copy)).status());
    if ((added + 1) % 1000 == 0) {
      std::fprintf(stderr, "insert_bench: %zu of %zu models (%.1f models/s)\n", active + added + 1,
                   target, double(added + 1) / secondsSince(t));
    }
  }
  return absl::OkStatus();
}

// Bench chair `k` (variant k mod 8, turned by 0.7·k rad about its vertical axis, at a place of its
// own in session "bench"), written into that session's map first.
gsm::RawSegment benchSegment(int64_t k, tsdf::TsdfLayer* scene) {
  const int variant = int(k % kKinds);
  const uint32_t label = uint32_t(k + 1);
  const Transform T_world_segment =
      poseFromXyzYaw({2.0 * double(k % 10), 2.0 * double(k / 10), 0.0}, 0.0);
  Eigen::Isometry3f T_segment_chair = Eigen::Isometry3f::Identity();
  T_segment_chair.linear() =
      Eigen::AngleAxisf(0.7f * float(k), Eigen::Vector3f::UnitZ()).toRotationMatrix();
  bench::addChair(scene, variant, T_world_segment.cast<float>() * T_segment_chair);
  bench::ChairGrid chair = bench::chairGrid(variant, T_segment_chair);
  std::vector<gsm::Label> voxel_parts(chair.surface_voxels.size(), label);
  return gsm::RawSegment{.label = label,
                         .T_world_segment = T_world_segment,
                         .grid = std::move(chair.grid),
                         .label_voxels = std::move(chair.surface_voxels),
                         .last_update_frame = 10 * k,
                         .extraction_frame = 10 * k + 10,
                         .observation_depth_m = kObservationDepthM,
                         .parts = {label},
                         .voxel_parts = std::move(voxel_parts)};
}

struct Options {
  std::vector<size_t> models = {1000, 3000, 10000};
  int inserts = 50;
  std::string target;  // SQLite path or PostgreSQL URI
  float epsilon = -1.0f;  // database.prefilter_epsilon (< 0: the default)
  bool recall = false;    // also the exhaustive vote per insert, for the prefilter's recall
  int shortlist = -1;     // database.shortlist (< 0: the default; 0: the vote over every model)
};

// One N: its fill, open and inserts.
struct Row {
  PrefilterRecall recall;
  ShortlistRecall shortlist;
  size_t models = 0;
  double fill_s = 0, open_s = 0;
  std::vector<double> ms;  // wall time of each insert
  size_t candidates = 0, merged = 0, unmatchable = 0, scene_checks = 0, scenes_missing = 0;
  database::InsertTimings timings;  // summed
  // Match ("what is this?") of chairs not inserted: wall time, the model build's part, and how
  // many found a model they would merge with.
  std::vector<double> match_ms, match_build_ms;
  size_t match_accepted = 0;
};

double quantile(std::vector<double> v, double q) {
  std::sort(v.begin(), v.end());
  return v[size_t(q * double(v.size() - 1))];
}

Status run(const Options& options) {
  Params params;  // the server's defaults (objdb-server without --config)
  if (options.epsilon >= 0.0f) params.database.prefilter_epsilon = options.epsilon;
  if (options.shortlist >= 0) params.database.shortlist = options.shortlist;
  std::fprintf(stderr, "insert_bench: building %d chair models\n", kKinds);
  std::vector<Kind> kinds;
  for (int v = 0; v < kKinds; ++v) {
    OBJDB_ASSIGN_OR_RETURN(model::ObjectModel m, bench::describedChairModel(v));
    auto grid = std::make_shared<const tsdf::TsdfLayer>(m.grid.clone());
    kinds.push_back({std::move(m), std::move(grid)});
  }
  OBJDB_ASSIGN_OR_RETURN(std::unique_ptr<storage::Store> store,
                         storage::openStore(options.target));
  OBJDB_ASSIGN_OR_RETURN(const std::vector<int64_t> existing, store->modelIds());
  if (!existing.empty()) {
    return absl::FailedPreconditionError(absl::StrFormat(
        "%s holds %d models already; give it an empty database", store->describe(),
        existing.size()));
  }
  const float voxel = kinds.front().grid->voxelSize();
  const int vps = kinds.front().grid->voxelsPerSide();
  OBJDB_ASSIGN_OR_RETURN(tsdf::TsdfLayer fill_scene, tsdf::TsdfLayer::create(voxel, vps));
  for (int v = 0; v < kKinds; ++v) bench::addChair(&fill_scene, v, fillPose(v).cast<float>());
  OBJDB_RETURN_IF_ERROR(store->putScene(
      kFillSession, std::make_shared<const tsdf::TsdfLayer>(std::move(fill_scene))));
  OBJDB_ASSIGN_OR_RETURN(tsdf::TsdfLayer bench_layer, tsdf::TsdfLayer::create(voxel, vps));
  const auto bench_scene = std::make_shared<tsdf::TsdfLayer>(std::move(bench_layer));
  const database::LiveScenes live =
      [bench_scene](const std::string& session) -> std::shared_ptr<const tsdf::TsdfLayer> {
    if (session == kBenchSession) return bench_scene;
    return nullptr;  // "fill": the store's
  };

  std::printf("insert_bench: %s; the server's default Params (database.threads %d, "
              "shortlist %d, max_candidates %d, stop_after_accepted %d, prefilter_epsilon %g); chairs "
              "at 1 cm, 500 described keypoints per filled model\n",
              store->describe().c_str(), params.database.threads, params.database.shortlist,
              params.database.max_candidates,
              params.database.stop_after_accepted, params.database.prefilter_epsilon);
  std::printf("2 cores, noisy; figures vary\n\n");
  std::printf("%9s %8s %8s %10s %8s %8s %8s %8s %11s %7s\n", "N models", "fill s", "open s",
              "median ms", "p90", "p99", "max", "mean", "candidates", "merged");
  std::vector<Row> rows;
  int64_t next_fill = 0, next_insert = 0;
  std::unique_ptr<database::ObjectDatabase> db;
  for (const size_t n : options.models) {
    db.reset();  // the fill writes past it: opened again below, as a restarted server would
    Row row;
    OBJDB_ASSIGN_OR_RETURN(const std::vector<int64_t> before, store->modelIds());
    auto t = Clock::now();
    OBJDB_RETURN_IF_ERROR(fill(store.get(), kinds, before.size(), n, &next_fill));
    row.fill_s = secondsSince(t);
    OBJDB_ASSIGN_OR_RETURN(const std::vector<int64_t> ids, store->modelIds());
    row.models = ids.size();
    t = Clock::now();
    OBJDB_ASSIGN_OR_RETURN(db, database::ObjectDatabase::create(params, store.get()));
    row.open_s = secondsSince(t);
    db->measurePrefilterRecall(options.recall);
    for (int j = 0; j < options.inserts; ++j, ++next_insert) {
      const gsm::RawSegment segment = benchSegment(next_insert, bench_scene.get());
      t = Clock::now();
      auto report = db->insertSegment(kBenchSession, segment, live);
      row.ms.push_back(1000.0 * secondsSince(t));
      if (!report.ok()) {
        return annotate(report.status(), absl::StrFormat("inserting bench chair %d into %d models",
                                                         next_insert, row.models));
      }
      row.candidates += report->candidates;
      row.merged += report->merged ? 1 : 0;
      row.unmatchable += report->matchable ? 0 : 1;
      for (const auto& r : report->results) {
        row.scene_checks += r.scene_checks;
        row.scenes_missing += r.scenes_missing;
      }
      row.timings += report->timings;
      row.recall.add(*report);
      row.shortlist.add(*report);
    }
    // Match of chairs that are not inserted (the next bench chairs, each drawn into the bench
    // session's map first, as a segment to be inserted would be).
    for (int j = 0; j < kMatches; ++j) {
      const gsm::RawSegment segment = benchSegment(next_insert + j, bench_scene.get());
      t = Clock::now();
      auto report = db->match(segment, live);
      row.match_ms.push_back(1000.0 * secondsSince(t));
      if (!report.ok()) return annotate(report.status(), "matching a bench chair");
      row.match_build_ms.push_back(report->timings.cloud_ms + report->timings.keypoints_ms +
                                   report->timings.descriptors_ms);
      row.match_accepted += !report->results.empty() && report->results.front().accepted;
    }
    double mean = 0;
    for (const double ms : row.ms) mean += ms;
    mean /= double(row.ms.size());
    std::printf("%9zu %8.1f %8.2f %10.0f %8.0f %8.0f %8.0f %8.0f %11.1f %6.0f%%\n", row.models,
                row.fill_s, row.open_s, quantile(row.ms, 0.5), quantile(row.ms, 0.9),
                quantile(row.ms, 0.99), quantile(row.ms, 1.0), mean,
                double(row.candidates) / double(row.ms.size()),
                100.0 * double(row.merged) / double(row.ms.size()));
    {
      const database::InsertTimings& t = row.timings;
      const double n = double(row.ms.size());
      std::printf("%9s steps, mean ms: model build %.0f, prefilter %.0f, load %.0f, "
                  "match + register %.0f, model check %.0f, scene check %.0f, store %.0f (merge "
                  "rebuilds incl.)\n",
                  "", (t.cloud_ms + t.keypoints_ms + t.descriptors_ms) / n, t.prefilter_ms / n,
                  t.load_ms / n, t.match_register_ms / n, t.model_verify_ms / n,
                  t.scene_verify_ms / n, t.store_ms / n);
      std::printf("%9s Match of %d chairs not inserted: median %.0f ms (model build %.0f ms), "
                  "%zu found a model they would merge with\n",
                  "", kMatches, quantile(row.match_ms, 0.5), quantile(row.match_build_ms, 0.5),
                  row.match_accepted);
      // Copies tie: the exhaustive vote breaks ties by model id, the approximate by its search.
      if (options.recall) {
        std::printf("%9s %s\n", "", row.recall.summary().c_str());
        std::printf("%9s %s\n", "", row.shortlist.summary().c_str());
      }
    }
    std::fflush(stdout);
    rows.push_back(std::move(row));
  }

  // Where the time goes (InsertReport::timings, mean per insert; the candidates' steps summed
  // over candidates evaluated on database.threads threads).
  std::printf("\nmean ms per insert: P+K+D (model build), prefilter, load candidates, matching + "
              "registration, model checks, scene checks, store (a merge's rebuild incl.)\n");
  std::printf("%9s %8s %9s %8s %9s %8s %8s %8s %13s %9s\n", "N models", "P+K+D", "prefilter",
              "load", "match+reg", "model", "scene", "store", "scene checks", "no scene");
  for (const Row& row : rows) {
    const database::InsertTimings& s = row.timings;
    const double n = double(row.ms.size());
    std::printf("%9zu %8.1f %9.1f %8.1f %9.1f %8.1f %8.1f %8.1f %13.1f %9zu\n", row.models,
                (s.cloud_ms + s.keypoints_ms + s.descriptors_ms) / n, s.prefilter_ms / n,
                s.load_ms / n, s.match_register_ms / n, s.model_verify_ms / n,
                s.scene_verify_ms / n, s.store_ms / n, double(row.scene_checks) / n,
                row.scenes_missing);
    if (row.unmatchable > 0) {
      std::fprintf(stderr, "insert_bench: %zu of the inserts at %zu models were not matchable\n",
                   row.unmatchable, row.models);
    }
  }
  return absl::OkStatus();
}

bool parseModels(const std::string& list, std::vector<size_t>* out) {
  out->clear();
  for (const absl::string_view part : absl::StrSplit(list, ',')) {
    size_t n = 0;
    if (!absl::SimpleAtoi(part, &n) || n < 1 || n > 1000000) return false;
    if (!out->empty() && n <= out->back()) return false;
    out->push_back(n);
  }
  return !out->empty();
}

}  // namespace
}  // namespace objdb

int main(int argc, char** argv) {
  using namespace objdb;
  Options options;
  std::string dir = "/tmp", db;
  bool ok = argc % 2 == 1;  // flags with their values
  for (int i = 1; ok && i + 1 < argc; i += 2) {
    const std::string name = argv[i], value = argv[i + 1];
    if (name == "--models") {
      ok = parseModels(value, &options.models);
    } else if (name == "--inserts") {
      ok = absl::SimpleAtoi(value, &options.inserts) && options.inserts >= 1 &&
           options.inserts <= 100000;
    } else if (name == "--dir") {
      dir = value;
    } else if (name == "--db") {
      db = value;
    } else if (name == "--epsilon") {
      ok = absl::SimpleAtof(value, &options.epsilon) && options.epsilon >= 0.0f;
    } else if (name == "--shortlist") {
      ok = absl::SimpleAtoi(value, &options.shortlist) && options.shortlist >= 0;
    } else if (name == "--recall") {
      ok = value == "on" || value == "off";
      options.recall = value == "on";
    } else {
      ok = false;
    }
  }
  if (!ok) {
    std::fprintf(stderr, "usage: insert_bench [--models N,N,... (ascending, each in [1, "
                 "1000000])] [--inserts 1..100000] [--dir DIR] [--db SQLITE_FILE|POSTGRES_URI] "
                 "[--epsilon E] [--shortlist N] [--recall on|off]\n");
    return 2;
  }
  setLogLevel("warn");
  // A file of our own under --dir (removed before and after), or the database the caller names,
  // which must hold no models (it is left filled).
  const bool own_file = db.empty();
  options.target =
      own_file ? (std::filesystem::path(dir) / "objdb_insert_bench.sqlite").string() : db;
  auto remove_own = [&] {
    if (!own_file) return;
    std::error_code ignored;
    for (const char* suffix : {"", "-wal", "-shm"}) {
      std::filesystem::remove(options.target + suffix, ignored);
    }
  };
  remove_own();
  const Status status = run(options);  // the store is closed when it returns
  remove_own();
  if (!status.ok()) {
    std::fprintf(stderr, "insert_bench: %s\n", std::string(status.message()).c_str());
    return 1;
  }
  return 0;
}
