// NOT the server's protocol (that is `objdb eval`): scenes first, a label's last extraction only.
// The paper's experiment (§IV, tables II–III) on the synthetic lounge, offline: the three
// sessions run through segmentation → GSM → object database with ground-truth poses, and the
// database is scored against the ground truth: raw segments, mergeable (non-planar) segments,
// object models, models built from ≥ 2 segments, erroneous merges (a model whose segments come
// from different object kinds), the share of repeated objects' segments that end up with
// another segment of their kind, and the time of each database step (P, K, D, MR, MV, SV).
// With --scale N it then copies the lounge's models into a database of N models and times
// inserting the last session's segments into it (the prefilter + parallel registration at
// scale; copies of a model share its descriptors, so the prefilter finds the most candidates it
// can: a worst case).
//   database_eval [--camera tango|vga] [--frames-per-session N] [--sessions N] [--threads N]
//                 [--scale N] [--config FILE.json] [--db FILE.sqlite] [--per-object]
//                 [--per-segment]
// With --db the database lives in that SQLite file (created anew) instead of memory: the same
// experiment with persistence, every insert and merge one transaction.
#include <malloc.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <set>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "absl/strings/str_format.h"
#include "bench/bench_util.h"
#include "bench/prefilter_recall.h"
#include "core/common/grid_key.h"
#include "core/common/mesh_distance.h"
#include "core/completion/completion_score.h"
#include "core/completion/scene_completion.h"
#include "core/tsdf/mesh_extraction.h"
#include "core/common/params_io.h"
#include "core/database/object_database.h"
#include "core/gsm/gsm.h"
#include "core/segmentation/depth_segmenter.h"
#include "core/sim/generator.h"
#include "core/sim/lounge.h"
#include "storage/sqlite/sqlite_store.h"

namespace {

using Clock = std::chrono::steady_clock;
double secondsSince(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

// Ground truth of a raw segment: the object most of its voxels belong to.
struct SegmentTruth {
  int object = 0;        // instance id (0: unknown)
  std::string kind;      // category, "structure" for floor and walls
  double purity = 0.0;   // share of its voxels on that object
};

}  // namespace

int main(int argc, char** argv) {
  using namespace objdb;
  bench::setUpBenchmarkProcess();
  std::string camera = "tango";
  int per_session = 300, sessions = 3;
  Params params;
  int threads = params.database.threads;
  int scale = 0;
  bool per_object = false, per_segment = false;
  std::string db_path;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--camera" && i + 1 < argc) {
      camera = argv[++i];
    } else if (a == "--frames-per-session" && i + 1 < argc) {
      per_session = std::max(1, std::atoi(argv[++i]));
    } else if (a == "--sessions" && i + 1 < argc) {
      sessions = std::clamp(std::atoi(argv[++i]), 1, 3);
    } else if (a == "--threads" && i + 1 < argc) {
      threads = std::max(1, std::atoi(argv[++i]));
    } else if (a == "--db" && i + 1 < argc) {
      db_path = argv[++i];
    } else if (a == "--per-object") {
      per_object = true;
    } else if (a == "--per-segment") {
      per_segment = true;
    } else if (a == "--scale" && i + 1 < argc) {
      scale = std::max(0, std::atoi(argv[++i]));
    } else if (a == "--config" && i + 1 < argc) {
      auto loaded = loadParamsFile(argv[++i]);
      if (!loaded.ok()) {
        std::fprintf(stderr, "database_eval: %s\n", std::string(loaded.status().message()).c_str());
        return 1;
      }
      params = *loaded;
    } else {
      std::fprintf(stderr, "usage: database_eval [--camera tango|vga] [--frames-per-session N] "
                           "[--sessions N] [--threads N] [--scale N] [--config FILE.json] "
                           "[--db FILE.sqlite] [--per-object] [--per-segment]\n");
      return 2;
    }
  }
  params.database.threads = threads;
  sim::LoungeOptions options;
  options.camera = camera;
  const std::vector<sim::Scene> scenes = sim::loungePreset(options).value();

  std::unique_ptr<database::ModelStore> store_owner;
  if (db_path.empty()) {
    store_owner = std::make_unique<database::InMemoryModelStore>();
  } else {
    for (const char* suffix : {"", "-wal", "-shm"}) std::filesystem::remove(db_path + suffix);
    auto opened = storage::SqliteStore::open(db_path);
    if (!opened.ok()) {
      std::fprintf(stderr, "database_eval: %s\n", std::string(opened.status().message()).c_str());
      return 1;
    }
    store_owner = std::move(*opened);
  }
  database::ModelStore& store = *store_owner;
  auto db = database::ObjectDatabase::create(params, &store);
  if (!db.ok()) {
    std::fprintf(stderr, "database_eval: %s\n", std::string(db.status().message()).c_str());
    return 1;
  }
  (*db)->measurePrefilterRecall(true);
  PrefilterRecall against_exhaustive;
  ShortlistRecall shortlist_recall;
  std::map<database::SegmentKey, SegmentTruth> truth_of;
  std::vector<std::pair<std::string, gsm::RawSegment>> last_session;  // for --scale
  // Per session: every non-structure object, its shape and pose.
  std::vector<sim::BuiltScene> built_scenes;  // keeps the object-frame meshes alive
  std::vector<completion::TrueInstance> true_objects;
  database::InsertTimings sum;
  size_t raw_segments = 0, mergeable = 0, planar = 0, skipped = 0;
  std::map<std::string, size_t> stages;  // candidate outcomes: stage where each stopped
  std::map<std::string, size_t> stages_same;  // the same, for candidates holding the segment's kind
  // After an accepted registration, the model-to-model numbers: candidates of the incoming
  // segment's kind, and of other kinds (where recall is lost, and how close the wrong ones get).
  std::vector<double> etsdf_same, etsdf_other, overlap_same, overlap_other;
  // Median chromaticity distance of the registered candidates (matching::compareColours).
  std::vector<double> colour_same, colour_other;
  double match_ms = 0, ransac_ms = 0, icp_ms = 0;
  // Prefilter recall: stored models holding a segment of the incoming segment's kind, and how
  // many of them the prefilter kept.
  size_t relevant_models = 0, relevant_kept = 0, inserts_with_relevant = 0, inserts_hit = 0;
  double gsm_seconds = 0.0;
  const auto start = Clock::now();
  std::printf("Object database on the synthetic lounge (%s, %d frames per session, %.0f mm "
              "voxels, %d threads)\n\n",
              camera.c_str(), per_session, params.tsdf.voxel_size_m * 1000, threads);
  for (int si = 0; si < sessions; ++si) {
    const sim::Scene& scene = scenes[size_t(si)];
    built_scenes.push_back(sim::buildScene(scene).value());
    const auto& built = built_scenes.back();
    const auto poses = sim::sampleTrajectory(scene.trajectory).value();
    const sim::Renderer renderer(scene.intrinsics);
    auto segmenter =
        segmentation::DepthSegmenter::create(params.segmentation, scene.intrinsics).value();
    gsm::Gsm map = gsm::Gsm::create(params.tsdf, params.gsm, scene.intrinsics).value();
    map.setNoiseModel(params.model);
    std::map<uint64_t, std::map<int, int>> truth;  // voxel → instance id → points
    std::map<gsm::Label, gsm::RawSegment> extracted;  // latest extraction per label
    last_session.clear();
    const auto t_gsm = Clock::now();
    const size_t step = std::max<size_t>(1, poses.size() / size_t(per_session));
    for (size_t i = 0; i < poses.size(); i += step) {
      const Frame f = sim::renderFrame(scene, built, renderer, poses[i], i, true);
      // With colour, as a stream brings it (the database's colour check reads it).
      const ColorImage* colour = f.color ? &*f.color : nullptr;
      const auto seg = segmenter.segment(f.depth, colour).value();
      (void)map.integrate(f.depth, seg.labels, f.T_world_camera, colour).value();
      for (auto& s : map.extractIdle()) extracted.insert_or_assign(s.label, std::move(s));
      for (const gsm::Label gone : map.takeWithdrawn()) extracted.erase(gone);  // merged away
      bench::forEachInstancePoint(f, scene.intrinsics, params.tsdf.max_ray_length_m,
                                  [&](const Eigen::Vector3f& p, uint16_t id) {
                                    ++truth[packGridKey(map.tsdf().voxelIndexOf(p))][id];
                                  });
    }
    for (auto& s : map.extractIdle(true)) extracted.insert_or_assign(s.label, std::move(s));
    for (const gsm::Label gone : map.takeWithdrawn()) extracted.erase(gone);
    gsm_seconds += secondsSince(t_gsm);
    const Status stored = store.putScene(scene.name, std::make_shared<tsdf::TsdfLayer>(map.tsdf().clone()));
    if (!stored.ok()) {
      std::fprintf(stderr, "database_eval: %s\n", std::string(stored.message()).c_str());
      return 1;
    }

    std::map<int, std::pair<std::string, bool>> objects;  // id → (kind, structure)
    for (const auto& o : scene.objects) objects[o.id] = {o.category, o.structure};
    for (const auto& instance : built.instances) {
      const auto o = objects.find(int(instance.instance_id));
      if (o == objects.end() || o->second.second) continue;
      true_objects.push_back({scene.name, o->second.first, int(instance.instance_id), instance.mesh,
                              instance.T_world_object});
    }
    size_t session_merges = 0;
    for (auto& [label, segment] : extracted) {
      // Ground truth: majority instance over the segment's voxels (world = segment + origin).
      std::map<int, int> votes;
      const Eigen::Isometry3f T = segment.T_world_segment.cast<float>();
      for (const auto& v : segment.label_voxels) {
        const tsdf::VoxelIndex w = map.tsdf().voxelIndexOf(T * segment.grid.voxelCenter(v));
        const auto it = truth.find(packGridKey(w));
        if (it == truth.end()) continue;
        int best = 0, n = 0;
        for (const auto& [id, c] : it->second) {
          if (c > n) {
            best = id;
            n = c;
          }
        }
        ++votes[best];
      }
      SegmentTruth t;
      int n = 0, total = 0;
      for (const auto& [id, c] : votes) {
        total += c;
        if (c > n) {
          t.object = id;
          n = c;
        }
      }
      t.purity = total ? double(n) / total : 0.0;
      const auto o = objects.find(t.object);
      t.kind = o == objects.end() ? "unknown" : (o->second.second ? "structure" : o->second.first);
      const database::SegmentKey key{scene.name, label};
      truth_of[key] = t;
      ++raw_segments;
      std::set<int64_t> relevant;
      if (t.kind != "structure" && t.kind != "unknown") {
        const std::vector<int64_t> ids_now = store.modelIds().value();
        for (int64_t id : ids_now) {
          const auto m = store.model(id).value();
          if (!m->matchable(params.model)) continue;
          for (const auto& o : m->observations) {
            if (truth_of[{o.session, o.label}].kind == t.kind) {
              relevant.insert(id);
              break;
            }
          }
        }
      }
      last_session.emplace_back(scene.name, gsm::RawSegment{segment.label, segment.T_world_segment,
                                                           segment.grid.clone(),
                                                           segment.label_voxels,
                                                           segment.last_update_frame,
                                                           segment.extraction_frame,
                                                           segment.observation_depth_m,
                                                           segment.parts, segment.voxel_parts});
      auto report = (*db)->insertSegment(scene.name, segment);
      if (!report.ok()) {
        std::fprintf(stderr, "insert %s/%u: %s\n", scene.name.c_str(), label,
                     std::string(report.status().message()).c_str());
        ++skipped;
        continue;
      }
      if (report->unusable) {  // no surface at the mesh weight: stored, held by no model
        ++skipped;
        continue;
      }
      against_exhaustive.add(*report);
      shortlist_recall.add(*report);
      if (report->matchable && !relevant.empty()) {
        size_t kept = 0;
        for (const auto& c : report->results) kept += relevant.count(c.model_id);
        relevant_models += relevant.size();
        relevant_kept += kept;
        ++inserts_with_relevant;
        inserts_hit += kept > 0 ? 1 : 0;
      }
      for (const auto& c : report->results) {
        match_ms += c.registration.match_ms;
        ransac_ms += c.registration.ransac_ms;
        icp_ms += c.registration.icp_ms;
        // The stage, and for rejections the first word of the reason (which threshold).
        const std::string outcome =
            c.accepted ? "accepted" : c.stage + ":" + c.reason.substr(0, c.reason.find(' '));
        ++stages[outcome];
        const bool same = relevant.count(c.model_id) > 0;
        if (same) ++stages_same[outcome];
        if (c.registration.accepted && !relevant.empty()) {
          (same ? etsdf_same : etsdf_other).push_back(c.model_verdict.agreement.rmse);
          (same ? overlap_same : overlap_other).push_back(double(c.model_verdict.agreement.overlap));
        }
        if (c.registration.accepted && c.colour.pairs > 0 && !relevant.empty()) {
          (same ? colour_same : colour_other).push_back(c.colour.median_distance);
        }
      }
      if (per_segment) {
        // One line per insert, then its candidates that hold the segment's kind: where each
        // stopped and why (the place to see why two views of one object did not merge).
        std::printf("segment %s/%u %s#%d (%.0f%%) %zu voxels: %s%s\n", scene.name.c_str(), label,
                    t.kind.c_str(), t.object, 100 * t.purity, segment.label_voxels.size(),
                    report->planar ? "planar" : (report->matchable ? "matchable" : "not describable"),
                    report->merged ? absl::StrFormat(", merged into model %lld",
                                                     (long long)report->model_id).c_str()
                                   : "");
        for (const auto& c : report->results) {
          if (!relevant.count(c.model_id)) continue;
          // The TSDF numbers exist once registration succeeded (the model check ran).
          const std::string numbers =
              c.registration.accepted
                  ? absl::StrFormat(" (e_TSDF %.1f mm, o_TSDF %d, colour %.3f over %d)",
                                    1000 * c.model_verdict.agreement.rmse,
                                    int64_t(c.model_verdict.agreement.overlap),
                                    c.colour.median_distance, int64_t(c.colour.pairs))
                  : "";
          std::printf("    candidate model %lld: %s%s%s\n", (long long)c.model_id,
                      c.accepted ? "accepted" : c.stage.c_str(),
                      c.accepted ? "" : (": " + c.reason).c_str(), numbers.c_str());
        }
        for (const auto& c : report->co_accepted) {
          std::printf("    model %lld (took the segment too) %s model %lld%s%s\n",
                      (long long)c.model_id, c.accepted ? "merged into" : "kept apart from",
                      (long long)report->model_id, c.accepted ? "" : ": ",
                      c.accepted ? "" : (c.stage + ": " + c.reason).c_str());
        }
      }
      planar += report->planar ? 1 : 0;
      mergeable += report->matchable ? 1 : 0;
      session_merges += report->merged ? 1 : 0;
      sum += report->timings;
    }
    std::printf("%s: %zu raw segments, %zu merged into earlier models, %zu models so far "
                "(%.1f s since start)\n",
                scene.name.c_str(), extracted.size(), session_merges, store.modelIds().value().size(),
                secondsSince(start));
  }

  // Scoring.
  size_t models = 0, multi = 0, erroneous = 0;
  std::map<std::string, size_t> kind_segments;  // matchable segments per kind
  std::map<database::SegmentKey, int64_t> model_of;
  std::map<int64_t, std::vector<database::SegmentKey>> members;
  const std::vector<int64_t> final_ids = store.modelIds().value();
  for (int64_t id : final_ids) {
    const auto m = store.model(id).value();
    ++models;
    std::set<std::string> kinds;
    for (const auto& o : m->observations) {
      const database::SegmentKey key{o.session, o.label};
      members[id].push_back(key);
      model_of[key] = id;
      kinds.insert(truth_of[key].kind);
    }
    if (m->observations.size() >= 2) {
      ++multi;
      if (kinds.size() >= 2) {
        ++erroneous;
        std::string list;
        for (const auto& o : m->observations) {
          const auto& t = truth_of[{o.session, o.label}];
          list += absl::StrFormat(" %s/%u=%s#%d(%.0f%%)", o.session, o.label, t.kind, t.object,
                                  100 * t.purity);
        }
        std::printf("erroneous merge: model %lld:%s\n", (long long)id, list.c_str());
      }
    }
    if (m->matchable(params.model) || m->observations.size() >= 2) {
      for (const auto& o : m->observations) ++kind_segments[truth_of[{o.session, o.label}].kind];
    }
  }
  // Repeated objects: kinds with ≥ 2 mergeable segments; did each end up with another of its kind?
  size_t repeated = 0, together = 0;
  for (const auto& [key, id] : model_of) {
    const auto& t = truth_of[key];
    if (t.kind == "structure" || t.kind == "unknown" || kind_segments[t.kind] < 2) continue;
    const auto m = store.model(id).value();
    if (!m->matchable(params.model) && m->observations.size() < 2) continue;
    ++repeated;
    for (const auto& other : members[id]) {
      if (!(other == key) && truth_of[other].kind == t.kind) {
        ++together;
        break;
      }
    }
  }
  std::printf("\n%-44s %8s\n", "", "lounge");
  std::printf("%-44s %8zu\n", "raw segments", raw_segments);
  std::printf("%-44s %8zu\n", "skipped (no surface at mesh weight)", skipped);
  std::printf("%-44s %8zu\n", "mergeable (non-planar, describable)", mergeable);
  std::printf("%-44s %8zu\n", "planar (stored, not matched)", planar);
  std::printf("%-44s %8zu\n", "object models", models);
  std::printf("%-44s %8zu\n", "models from >= 2 segments", multi);
  std::printf("%-44s %8zu\n", "erroneous merges (kinds differ)", erroneous);
  std::printf("%-44s %7.0f%%  (%zu of %zu; target >= 80 %%)\n",
              "repeated objects' segments with their kind", repeated ? 100.0 * together / repeated : 0.0,
              together, repeated);
  size_t evaluated = 0;
  for (const auto& [stage, n] : stages) evaluated += n;
  std::printf("\ncandidates evaluated: %zu (%.1f per mergeable insert); outcome:", evaluated,
              mergeable ? double(evaluated) / double(mergeable) : 0.0);
  for (const auto& [stage, n] : stages) std::printf(" %s %zu", stage.c_str(), n);
  std::printf("\n  of them holding the segment's kind:");
  for (const auto& [stage, n] : stages_same) std::printf(" %s %zu", stage.c_str(), n);
  auto quantiles = [](std::vector<double> v, double scale) {
    if (v.empty()) return std::string("none");
    std::sort(v.begin(), v.end());
    auto at = [&](double q) { return scale * v[size_t(q * double(v.size() - 1))]; };
    return absl::StrFormat("%zu, min %.1f, p10 %.1f, median %.1f, p90 %.1f", v.size(), at(0.0),
                           at(0.1), at(0.5), at(0.9));
  };
  std::printf("\n  registered, e_TSDF mm: same kind %s; other kinds %s",
              quantiles(etsdf_same, 1000.0).c_str(), quantiles(etsdf_other, 1000.0).c_str());
  std::printf("\n  registered, o_TSDF voxels: same kind %s; other kinds %s",
              quantiles(overlap_same, 1.0).c_str(), quantiles(overlap_other, 1.0).c_str());
  std::printf("\n  registered, median chromaticity distance x1000: same kind %s; "
              "other kinds %s",
              quantiles(colour_same, 1000.0).c_str(), quantiles(colour_other, 1000.0).c_str());
  std::printf("\nprefilter recall: %.0f %% of the stored models of the same kind kept as "
              "candidates (%zu of %zu); %zu of %zu inserts kept at least one\n",
              relevant_models ? 100.0 * relevant_kept / relevant_models : 0.0, relevant_kept,
              relevant_models, inserts_hit, inserts_with_relevant);
  std::printf("%s (database.shortlist %d)\n", shortlist_recall.summary().c_str(),
              params.database.shortlist);
  if (against_exhaustive.inserts > 0) {
    std::printf("%s (epsilon %g)\n", against_exhaustive.summary().c_str(),
                params.database.prefilter_epsilon);
  }
  std::printf("\nMR split, seconds: descriptor matching %.1f, RANSAC %.1f, ICP %.1f\n",
              match_ms / 1000, ransac_ms / 1000, icp_ms / 1000);
  std::printf("\nTime of the database stage, seconds (paper table II; one insert at a time, "
              "candidates on %d threads)\n",
              threads);
  std::printf("%8s %8s %8s %8s %8s %8s %8s %10s\n", "P", "K", "D", "MR", "MV", "SV", "sum",
              "wall");
  std::printf("%8.1f %8.1f %8.1f %8.1f %8.1f %8.1f %8.1f %10.1f\n", sum.cloud_ms / 1000,
              sum.keypoints_ms / 1000, sum.descriptors_ms / 1000, sum.match_register_ms / 1000,
              sum.model_verify_ms / 1000, sum.scene_verify_ms / 1000,
              (sum.cloud_ms + sum.keypoints_ms + sum.descriptors_ms + sum.match_register_ms +
               sum.model_verify_ms + sum.scene_verify_ms) /
                  1000,
              sum.total_ms / 1000);
  std::printf("paper (Xeon 2.8 GHz, one thread): sum 1372.6 s, 1267.6 s of it matching and "
              "registration. Segmentation + GSM took %.1f s here (not in the table).\n",
              gsm_seconds);
  std::printf("P: surface cloud + planarity; K: keypoints; D: descriptors; MR: matching and "
              "registration (summed over candidates and threads); MV: model-to-model TSDF "
              "check; SV: model-to-scene checks; wall: insert calls end to end.\n");
  // Completion gain: for objects of kinds seen more than once, the share of their true surface
  // within 2 cm of the session's reconstruction, before and after completion. The ceiling is what
  // a perfect completion could reach: a surface point counts when some instance of the same
  // shape, in any session, has it reconstructed (ground-truth poses; no database involved).
  {
    std::map<std::string, MeshDistance> before_of, after_of;
    // (session, instance) → verified placements on its segments, surface voxels they filled
    std::map<std::pair<std::string, int>, std::pair<size_t, size_t>> placed_on;
    size_t placements = 0, verified = 0, added_vertices = 0, added_on_truth = 0;
    for (int si = 0; si < sessions; ++si) {
      const std::string& name = scenes[size_t(si)].name;
      const auto scene = store.scene(name).value();
      completion::CompletionReport report;
      auto completed =
          completion::completeScene(store, name, params.merging, params.tsdf, &report);
      if (!completed.ok()) continue;
      placements += report.placements.size();
      for (const auto& p : report.placements) {
        verified += p.verified ? 1 : 0;
        const auto truth = truth_of.find({name, p.label});
        if (truth == truth_of.end()) continue;
        auto& [placed, filled] = placed_on[{name, truth->second.object}];
        placed += p.verified ? 1 : 0;
        filled += p.filled_surface_voxels;
      }
      const TriangleMesh after_mesh = tsdf::extractMesh(*completed, params.tsdf.mesh_min_weight);
      before_of.emplace(
          name, MeshDistance::create(tsdf::extractMesh(*scene, params.tsdf.mesh_min_weight), 0.02f)
                    .value());
      after_of.emplace(name, MeshDistance::create(after_mesh, 0.02f).value());
      // What completion added (surface farther than 2 cm from the measured reconstruction), and
      // how much of it lies on a true surface of the scene (objects, floor and walls).
      const auto truth_index =
          MeshDistance::create(sim::trueSurface(built_scenes[size_t(si)]), 0.02f).value();
      for (const auto& v : completion::addedVertices(after_mesh, before_of.at(name))) {
        ++added_vertices;
        added_on_truth += truth_index.distance(v) <= 0.02f ? 1 : 0;
      }
    }
    std::map<std::string, const MeshDistance*> before, after;
    for (const auto& [name, index] : before_of) before[name] = &index;
    for (const auto& [name, index] : after_of) after[name] = &index;
    const auto gain = completion::surfaceGain(true_objects, before, after, 0.02f).value();
    if (per_object) {
      std::printf("\n%-10s %4s %-18s %8s %8s %8s %7s %7s\n", "session", "id", "kind", "before",
                  "after", "ceiling", "placed", "filled");
      for (const auto& g : gain.instances) {
        const auto& t = true_objects[g.instance];
        const auto placed = placed_on.find({t.session, t.id});
        std::printf("%-10s %4d %-18s %7.1f%% %7.1f%% %7.1f%% %7zu %7zu\n", t.session.c_str(), t.id,
                    t.kind.c_str(), 100.0 * g.before, 100.0 * g.after, 100.0 * g.ceiling,
                    placed == placed_on.end() ? size_t(0) : placed->second.first,
                    placed == placed_on.end() ? size_t(0) : placed->second.second);
      }
    }
    std::printf("\ncompletion: %zu placements of multi-segment models, %zu verified against "
                "their scene; repeated objects' true surface within 2 cm of the reconstruction: "
                "%.1f %% before, %.1f %% after (+%.1f points; target +8) over %zu object "
                "instances; ceiling (every instance of the shape, any session) %.1f %% "
                "(+%.1f points)\n",
                placements, verified, 100.0 * gain.before, 100.0 * gain.after,
                100.0 * (gain.after - gain.before), gain.instances.size(), 100.0 * gain.ceiling,
                100.0 * (gain.ceiling - gain.before));
    std::printf("completion added %zu mesh vertices (farther than 2 cm from the measured "
                "surface); %.1f %% of them lie within 2 cm of a true surface of the scene "
                "(precision)\n",
                added_vertices,
                added_vertices ? 100.0 * double(added_on_truth) / double(added_vertices) : 0.0);
  }

  if (scale > 0) {
    // A database of `scale` models: copies of the lounge's, each under its own session name
    // (with the raw segments and scene maps it refers to), then the last session inserted again.
    database::InMemoryModelStore big;
    const std::vector<int64_t> ids = store.modelIds().value();
    const auto t_fill = Clock::now();
    for (int c = 0; c < scale; ++c) {
      const auto source = store.model(ids[size_t(c) % ids.size()]).value();
      model::ObjectModel copy = model::cloneModel(*source);
      const std::string prefix = absl::StrFormat("copy%d/", c);
      for (auto& o : copy.observations) {
        auto segment = *store.rawSegment({o.session, o.label}).value();
        if (big.scene(prefix + o.session).value() == nullptr) {
          (void)big.putScene(prefix + o.session, store.scene(o.session).value());
        }
        o.session = prefix + o.session;
        segment.key.session = o.session;
        (void)big.putRawSegment(segment);
      }
      (void)big.addModel(std::move(copy));
    }
    for (int si = 0; si < sessions; ++si) {
      (void)big.putScene(scenes[size_t(si)].name, store.scene(scenes[size_t(si)].name).value());
    }
    auto big_db = database::ObjectDatabase::create(params, &big).value();
    std::printf("\nDatabase of %d models (copies of the lounge's %zu) filled in %.1f s; inserting "
                "the %zu segments of the last session:\n",
                scale, ids.size(), secondsSince(t_fill), last_session.size());
    std::vector<double> ms;
    size_t most_candidates = 0;
    database::InsertReport slowest;
    for (const auto& [session, segment] : last_session) {
      const auto t = Clock::now();
      auto report = big_db->insertSegment(session, segment);
      if (!report.ok() || !report->matchable) continue;
      ms.push_back(1000.0 * secondsSince(t));
      most_candidates = std::max(most_candidates, report->candidates);
      if (ms.back() == *std::max_element(ms.begin(), ms.end())) slowest = *report;
    }
    std::sort(ms.begin(), ms.end());
    if (!ms.empty()) {
      const auto& s = slowest.timings;
      std::printf("slowest insert: %.0f ms = replacing an earlier contribution %.0f, "
                  "cloud+planarity %.0f, keypoints %.0f, descriptors %.0f, prefilter %.0f, "
                  "loading %zu candidates %.0f, matching+registration %.0f, model checks %.0f, "
                  "scene checks %.0f (these three summed over candidates, on %d threads), "
                  "storing the result %.0f\n",
                  s.total_ms, s.replace_ms, s.cloud_ms, s.keypoints_ms, s.descriptors_ms,
                  s.prefilter_ms, slowest.candidates, s.load_ms, s.match_register_ms,
                  s.model_verify_ms, s.scene_verify_ms, params.database.threads, s.store_ms);
    }
    if (!ms.empty()) {
      double mean = 0;
      for (double v : ms) mean += v;
      mean /= double(ms.size());
      std::printf("matchable inserts %zu: mean %.0f ms, median %.0f ms, max %.0f ms (target < 1 s); "
                  "at most %zu candidates after the prefilter (max_candidates %d)\n",
                  ms.size(), mean, ms[ms.size() / 2], ms.back(), most_candidates,
                  params.database.max_candidates);
    }
  }
  return 0;
}
