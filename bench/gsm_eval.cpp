// Segmentation + GSM on the synthetic lounge with ground-truth poses (paper §III-A/B): time per
// frame (segmentation, GSM integration), labels, bytes per voxel, and label quality against the
// ground truth: for every object its best GSM label's share of the object's voxels, and the
// labels that span two objects.
//   gsm_eval [--camera vga|tango] [--voxel-size M] [--frames-per-session N] [--sessions N]
#include <malloc.h>

#include <chrono>
#include <future>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <random>
#include <set>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "absl/strings/str_format.h"
#include "bench/bench_util.h"
#include "core/common/grid_key.h"
#include "core/common/mesh_distance.h"
#include "core/common/params_io.h"
#include "core/gsm/gsm.h"
#include "core/tsdf/mesh_extraction.h"
#include "core/segmentation/depth_segmenter.h"
#include "core/sim/generator.h"
#include "core/sim/lounge.h"

namespace {
double msSince(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t).count();
}
}  // namespace

int main(int argc, char** argv) {
  using namespace objdb;
  bench::setUpBenchmarkProcess();
  std::string camera = "vga";
  float voxel = 0.02f;
  int per_session = 100, sessions = 1;
  double label_noise = 0.0;
  bool verbose = false;
  Params params;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--camera" && i + 1 < argc) {
      camera = argv[++i];
    } else if (a == "--voxel-size" && i + 1 < argc) {
      voxel = float(std::atof(argv[++i]));
    } else if (a == "--frames-per-session" && i + 1 < argc) {
      per_session = std::max(1, std::atoi(argv[++i]));
    } else if (a == "--label-noise" && i + 1 < argc) {
      label_noise = std::clamp(std::atof(argv[++i]), 0.0, 1.0);
    } else if (a == "--config" && i + 1 < argc) {
      auto loaded = loadParamsFile(argv[++i]);
      if (!loaded.ok()) {
        std::fprintf(stderr, "gsm_eval: %s\n", std::string(loaded.status().message()).c_str());
        return 1;
      }
      params = *loaded;
    } else if (a == "--per-object") {
      verbose = true;
    } else if (a == "--sessions" && i + 1 < argc) {
      sessions = std::clamp(std::atoi(argv[++i]), 1, 3);
    } else {
      std::fprintf(stderr, "usage: gsm_eval [--camera vga|tango] [--voxel-size M] "
                           "[--frames-per-session N] [--sessions N] [--label-noise P] "
                           "[--per-object] [--config FILE.json]\n");
      return 2;
    }
  }
  // Inconsistent per-frame segmentation, for the ablation: with probability P a segment's pixels
  // take the label of another segment of the frame (a false join). Seeded by the frame index, so
  // both modes see the same perturbed frames.
  auto perturb = [label_noise](segmentation::LabelImage* labels, size_t frame) {
    if (label_noise <= 0.0) return;
    int32_t n = 0;
    for (int32_t l : labels->data) n = std::max(n, l);
    if (n < 2) return;
    std::mt19937 rng(uint32_t(frame) * 7919u + 17u);
    std::uniform_real_distribution<double> coin(0.0, 1.0);
    std::uniform_int_distribution<int32_t> pick(1, n);
    std::vector<int32_t> to(size_t(n) + 1);
    for (int32_t s = 0; s <= n; ++s) to[size_t(s)] = s;
    for (int32_t s = 1; s <= n; ++s) {
      if (coin(rng) < label_noise) to[size_t(s)] = pick(rng);
    }
    for (int32_t& l : labels->data) l = to[size_t(l)];
  };
  sim::LoungeOptions options;
  options.camera = camera;
  const std::vector<sim::Scene> scenes = sim::loungePreset(options).value();
  std::printf("Segmentation + GSM, lounge, %s, %.0f mm voxels, %d frames per session, "
              "label noise %.2f\n\n",
              camera.c_str(), voxel * 1000, per_session, label_noise);
  std::printf("%-10s %-7s %8s %8s %8s %8s %7s %8s %10s %11s %12s\n", "session", "mode", "seg ms",
              "gsm ms", "sum ms", "Hz", "labels", "merges", "best cov.", "union cov.",
              "span 2 obj.");
  for (int run = 0; run < 2 * sessions; ++run) {
    const int si = run / 2;
    const bool history = run % 2 == 0;
    const sim::Scene& scene = scenes[size_t(si)];
    GsmParams gsm_params = params.gsm;
    gsm_params.label_history = history;
    const auto built = sim::buildScene(scene).value();
    const auto poses = sim::sampleTrajectory(scene.trajectory).value();
    const sim::Renderer renderer(scene.intrinsics);
    auto segmenter = segmentation::DepthSegmenter::create(params.segmentation, scene.intrinsics).value();
    TsdfParams tsdf = params.tsdf;
    tsdf.voxel_size_m = voxel;
    tsdf.truncation_voxels = 0.06f / voxel;  // 6 cm at every voxel size (3 voxels at 2 cm)
    gsm::Gsm map = gsm::Gsm::create(tsdf, gsm_params, scene.intrinsics).value();
    std::set<uint16_t> structure;
    for (const auto& o : scene.objects) {
      if (o.structure) structure.insert(uint16_t(o.id));
    }
    // Ground truth per voxel: the instance ids voted the same way the GSM votes its labels.
    std::map<uint64_t, gsm::LabelVoxel> truth;
    double seg_ms = 0, gsm_ms = 0;
    size_t merges = 0, frames = 0;
    const size_t step = std::max<size_t>(1, poses.size() / size_t(per_session));
    for (size_t i = 0; i < poses.size(); i += step) {
      const Frame f = sim::renderFrame(scene, built, renderer, poses[i], i, false);
      auto t = std::chrono::steady_clock::now();
      auto seg = segmenter.segment(f.depth).value();
      seg_ms += msSince(t);
      perturb(&seg.labels, i);
      t = std::chrono::steady_clock::now();
      const auto r = map.integrate(f.depth, seg.labels, f.T_world_camera).value();
      gsm_ms += msSince(t);
      merges += r.merges;
      ++frames;
      bench::forEachInstancePoint(f, scene.intrinsics, tsdf.max_ray_length_m,
                                  [&](const Eigen::Vector3f& p, uint16_t id) {
                                    truth[packGridKey(map.tsdf().voxelIndexOf(p))].vote(id);
                                  });
    }
    // Throughput on two cores: segmentation of frame k+1 overlaps GSM fusion of frame k
    // (docs/architecture.md, "Threads"). Frames are rendered first so only the pipeline is timed.
    std::vector<Frame> input;
    for (size_t i = 0; i < poses.size(); i += step) {
      input.push_back(sim::renderFrame(scene, built, renderer, poses[i], i, false));
    }
    gsm::Gsm pipelined = gsm::Gsm::create(tsdf, gsm_params, scene.intrinsics).value();
    auto pipe_segmenter =
        segmentation::DepthSegmenter::create(params.segmentation, scene.intrinsics).value();
    const auto pipe_start = std::chrono::steady_clock::now();
    std::future<segmentation::SegmentationResult> next = std::async(std::launch::async, [&] {
      return pipe_segmenter.segment(input[0].depth).value();
    });
    for (size_t i = 0; i < input.size(); ++i) {
      segmentation::SegmentationResult current = next.get();
      if (i + 1 < input.size()) {
        next = std::async(std::launch::async,
                          [&, i] { return pipe_segmenter.segment(input[i + 1].depth).value(); });
      }
      (void)pipelined.integrate(input[i].depth, current.labels, input[i].T_world_camera).value();
    }
    const double pipeline_hz = 1000.0 * double(input.size()) / msSince(pipe_start);

    // Label quality, of the GSM's labels (parts) and of its objects (core/gsm/objects.h: each
    // label counted as the object it belongs to).
    struct Quality {
      double sum = 0, worst = 1, union_sum = 0, union_worst = 1;
      int objects = 0;
      size_t spanning = 0, units = 0;
      std::string per_object;
    };
    const auto group_start = std::chrono::steady_clock::now();
    const gsm::ObjectGroups groups = map.groupObjects();
    const double group_ms = msSince(group_start);
    const auto score = [&](bool as_objects) {
      const auto unit = [&](gsm::Label l) {
        if (!as_objects) return l;
        const auto it = groups.object_of.find(l);
        return it == groups.object_of.end() ? l : it->second;
      };
      // Per object: voxels, and how many of them each unit (label or object) holds.
      std::map<uint16_t, size_t> object_voxels;
      std::map<uint16_t, std::map<gsm::Label, size_t>> by_label;
      std::map<gsm::Label, std::map<uint16_t, size_t>> label_objects;
      for (const auto& [key, voxel_truth] : truth) {
        const uint16_t id = uint16_t(voxel_truth.mainLabel());
        const tsdf::VoxelIndex x = unpackGridKey(key);
        // As objects, an annexed structure voxel counts as the object that took it.
        const gsm::Label l = as_objects ? groups.partAt(x, map.mainLabel(x)) : map.mainLabel(x);
        ++object_voxels[id];
        if (l != 0) {
          ++by_label[id][unit(l)];
          ++label_objects[unit(l)][id];
        }
      }
      // Each unit's majority object: the units "mostly inside" an object, whose union credits
      // an object the segmenter cut into parts.
      std::map<gsm::Label, uint16_t> majority_of;
      for (const auto& [l, objects_in] : label_objects) {
        size_t most = 0;
        for (const auto& [id, c] : objects_in) {
          if (c > most) {
            most = c;
            majority_of[l] = id;
          }
        }
      }
      Quality q;
      for (const auto& [id, n] : object_voxels) {
        if (structure.count(id)) continue;
        size_t best = 0, parts = 0, labelled = 0, in_union = 0;
        std::string big;  // the units above 10 %: unit id, share, whose majority it is
        for (const auto& [l, c] : by_label[id]) {
          best = std::max(best, c);
          parts += c * 10 > n ? 1 : 0;
          if (c * 10 > n) {
            big += absl::StrFormat(
                "%s%u %.2f%s", big.empty() ? "" : ", ", l, double(c) / double(n),
                majority_of[l] == id ? "" : absl::StrFormat(" of %d", majority_of[l]));
          }
          labelled += c;
          in_union += majority_of[l] == id ? c : 0;
        }
        const double share = double(best) / double(n);
        const double union_share = double(in_union) / double(n);
        q.union_worst = std::min(q.union_worst, union_share);
        q.union_sum += union_share;
        std::string kind;
        for (const auto& o : scene.objects) {
          if (uint16_t(o.id) == id) kind = o.category;
        }
        q.per_object += absl::StrFormat(
            "%s%d %s %.2f, union %.2f (%zu %s > 10 %%: %s; %.0f %% unlabelled)",
            q.per_object.empty() ? "" : "; ", id, kind, share, union_share, parts,
            as_objects ? "objects" : "labels", big, 100.0 * (1.0 - double(labelled) / double(n)));
        q.worst = std::min(q.worst, share);
        q.sum += share;
        ++q.objects;
      }
      for (const auto& [l, objects_in] : label_objects) {
        size_t total = 0, above = 0;
        for (const auto& [id, c] : objects_in) total += c;
        for (const auto& [id, c] : objects_in) above += c > total / 10 ? 1 : 0;
        // Only units the database would get: smaller ones are never extracted.
        if (total < size_t(gsm_params.min_label_voxels)) continue;
        ++q.units;
        q.spanning += above >= 2 ? 1 : 0;
        if (verbose && above >= 2) {
          std::string parts;
          for (const auto& [id, c] : objects_in) {
            if (c > total / 10) parts += absl::StrFormat(" %d:%zu", id, c);
          }
          std::printf("%-10s %s %u spans objects (id:voxels)%s of %zu voxels\n", "",
                      as_objects ? "object" : "label", l, parts.c_str(), total);
        }
      }
      return q;
    };
    const Quality parts = score(false);
    const Quality whole = score(true);
    const auto mean = [](double sum, int n) { return n ? sum / n : 0.0; };
    std::printf("%-10s %-7s %8.2f %8.2f %8.2f %8.1f %7zu %8zu %5.2f/%4.2f  %5.2f/%4.2f %6zu/%zu\n",
                scene.name.c_str(), history ? "history" : "single", seg_ms / double(frames),
                gsm_ms / double(frames), (seg_ms + gsm_ms) / double(frames),
                1000.0 * double(frames) / (seg_ms + gsm_ms), map.numLabels(), merges,
                mean(parts.sum, parts.objects), parts.worst, mean(parts.union_sum, parts.objects),
                parts.union_worst, parts.spanning, parts.units);
    std::printf("%-10s %-7s %45s %5.2f/%4.2f  %5.2f/%4.2f %6zu/%zu   (%zu objects, grouped in "
                "%.1f ms)\n",
                "", "objects", "", mean(whole.sum, whole.objects), whole.worst,
                mean(whole.union_sum, whole.objects), whole.union_worst, whole.spanning,
                whole.units, groups.members.size(), group_ms);
    if (verbose) {
      std::printf("%-10s per object, labels: %s\n", "", parts.per_object.c_str());
      std::printf("%-10s per object, objects: %s\n", "", whole.per_object.c_str());
    }
    std::printf("%-10s pipelined on 2 threads (segment k+1 while fusing k): %.1f Hz\n", "",
                pipeline_hz);
    if (history) {
      // Surface accuracy (the TSDF is the same in both modes): mean distance of the mesh
      // vertices to the true surfaces of the scene, searched up to 5 cm.
      const TriangleMesh surface = tsdf::extractMesh(map.tsdf(), tsdf.mesh_min_weight);
      const auto index = MeshDistance::create(sim::trueSurface(built), 0.05f).value();
      std::vector<float> distances;
      distances.reserve(surface.vertices.size());
      for (const auto& v : surface.vertices) distances.push_back(index.distance(v));
      const DistanceStats d = summarizeDistances(std::move(distances));
      std::printf("%-10s surface accuracy of %zu mesh vertices: mean %.1f mm, median %.1f, p90 "
                  "%.1f, beyond 5 cm %.2f %% (target: mean <= half a voxel, %.0f mm)\n",
                  "", surface.vertices.size(), 1000.0 * d.mean, 1000.0 * d.median, 1000.0 * d.p90,
                  100.0 * double(d.beyond) / double(std::max<size_t>(1, d.count + d.beyond)),
                  500.0 * voxel);
    }
    std::printf("%-10s %zu TSDF blocks (%.1f MB), labels %.1f MB: %zu bytes per voxel incl. labels\n", "",
                map.tsdf().numBlocks(), double(map.tsdf().voxelBytes()) / 1e6,
                double(map.labelBytes()) / 1e6, sizeof(tsdf::TsdfVoxel) + sizeof(gsm::LabelVoxel));
  }
  std::printf("\nhistory: label-count history per voxel (the paper); single: one label + "
              "confidence per voxel (Tateno et al., the ablation).\n");
  std::printf("best cov.: mean / worst over objects (floor, walls excluded) of the best GSM "
              "label's share of the object's voxels; union cov.: the same for the labels whose "
              "majority is the object, together; span 2 obj.: labels with >= 2 objects above "
              "10 %% of their voxels / labels with at least min_label_voxels voxels (the ones "
              "extraction hands to the database). objects: the same for the GSM's objects "
              "(core/gsm/objects.h: each label counted as the object it belongs to). One "
              "thread.\n");
  return 0;
}
