// Depth segmentation (paper §III-A) on the synthetic lounge: per-step timings (one thread, and
// throughput with one segmenter per thread) and quality against the ground-truth instance masks,
// noisy vs noise-free, at VGA and Tango resolution. Usage:
//   segmentation_eval [--frames-per-session N] [--camera vga|tango|both] [--threads N]
#include <malloc.h>

#include <cstdio>
#include <cstdlib>
#include <map>
#include <string>
#include <thread>
#include <vector>

#include <opencv2/core.hpp>

#include "bench/bench_util.h"
#include "core/common/params_io.h"
#include "core/segmentation/depth_segmenter.h"
#include "core/segmentation/quality.h"
#include "core/gsm/gsm.h"
#include "core/sim/generator.h"
#include "core/sim/lounge.h"

namespace objdb {
namespace {

struct Sample {
  Frame frame;
  std::set<uint16_t> structure;
  std::map<uint16_t, std::string> kind;
};

std::vector<Sample> renderFrames(const std::string& camera, bool noise, int per_session) {
  sim::LoungeOptions options;
  options.camera = camera;
  options.noise = noise;
  std::vector<Sample> samples;
  const std::vector<sim::Scene> scenes = sim::loungePreset(options).value();
  for (const auto& scene : scenes) {
    const auto built = sim::buildScene(scene).value();
    const auto poses = sim::sampleTrajectory(scene.trajectory).value();
    const sim::Renderer renderer(scene.intrinsics);
    std::set<uint16_t> structure;
    std::map<uint16_t, std::string> kind;
    for (const auto& o : scene.objects) {
      if (o.structure) structure.insert(uint16_t(o.id));
      kind[uint16_t(o.id)] = o.category;
    }
    const size_t step = std::max<size_t>(1, poses.size() / size_t(per_session));
    for (size_t i = 0; i < poses.size(); i += step) {
      samples.push_back(
          {sim::renderFrame(scene, built, renderer, poses[i], i, false), structure, kind});
    }
  }
  return samples;
}

struct KindScore {
  double weighted_iou = 0.0, weighted_union_iou = 0.0, pixels = 0.0;
  // Where the object's pixels went (sums over frames): no depth measurement, valid but on a
  // boundary / in a dropped region (label 0), in the object's best segment, in other segments;
  // and the pixels of the observations in which no segment has IoU ≥ 0.1 with the object.
  double no_depth = 0.0, unlabelled = 0.0, in_best = 0.0, elsewhere = 0.0, lost = 0.0;
};

// Adds the pixel breakdown of every scored object of one frame to `per_kind`.
void addBreakdown(const Sample& s, const segmentation::LabelImage& labels,
                  const std::map<uint16_t, segmentation::ObjectScore>& scores,
                  std::map<std::string, KindScore>* per_kind) {
  for (const auto& [id, score] : scores) {
    if (score.best_iou < 0.1) (*per_kind)[s.kind.at(id)].lost += double(score.pixels);
  }
  const InstanceImage& inst = *s.frame.instances;
  for (size_t i = 0; i < inst.data.size(); ++i) {
    const auto it = scores.find(inst.data[i]);
    if (it == scores.end()) continue;  // background, structure or too small to score
    KindScore& k = (*per_kind)[s.kind.at(it->first)];
    if (!isValidDepth(s.frame.depth.data[i])) {
      k.no_depth += 1;
    } else if (labels.data[i] == 0) {
      k.unlabelled += 1;
    } else if (labels.data[i] == it->second.best_label) {
      k.in_best += 1;
    } else {
      k.elsewhere += 1;
    }
  }
}

struct RunResult {
  segmentation::QualityCounts quality;
  // The frame's segments grouped into objects (core/gsm/objects.h) on a map of that frame alone.
  segmentation::QualityCounts object_quality;
  std::map<std::string, KindScore> per_kind;
  segmentation::SegmentationTimings timings;  // mean per frame
  double throughput_fps = 0;
};

// The frame's segment labels replaced by the object each belongs to: the frame fused alone into a
// fresh GSM (2 cm), its labels grouped as the GSM groups a map.
segmentation::LabelImage objectLabels(const Sample& s, const segmentation::LabelImage& labels,
                                      const Intrinsics& k, const Params& params) {
  TsdfParams tsdf = params.tsdf;
  tsdf.voxel_size_m = 0.02f;
  gsm::Gsm map = gsm::Gsm::create(tsdf, params.gsm, k).value();
  const gsm::GsmFrameResult fused = map.integrate(s.frame.depth, labels, s.frame.T_world_camera).value();
  const gsm::ObjectGroups groups = map.groupObjects();
  segmentation::LabelImage out = labels;
  for (int32_t& l : out.data) {
    if (l <= 0 || size_t(l) > fused.segment_labels.size()) continue;
    const auto it = groups.object_of.find(fused.segment_labels[size_t(l - 1)]);
    l = it == groups.object_of.end() ? l + (1 << 20) : int32_t(it->second);  // ungrouped: its own
  }
  return out;
}

RunResult run(const std::vector<Sample>& samples, const Intrinsics& k, int threads,
             const Params& all_params) {
  const SegmentationParams& params = all_params.segmentation;
  RunResult r;
  auto segmenter = segmentation::DepthSegmenter::create(params, k).value();
  // Warm-up, untimed: the first frames of a process pay first-touch page faults for the
  // segmenter's buffers and the heap (a long-running server pays them once).
  for (size_t i = 0; i < std::min<size_t>(samples.size(), 5); ++i) {
    (void)segmenter.segment(samples[i].frame.depth);
  }
  size_t n = 0;
  for (const auto& s : samples) {
    auto result = segmenter.segment(s.frame.depth).value();
    segmentation::QualityOptions qo;
    qo.structure_ids = s.structure;
    std::map<uint16_t, segmentation::ObjectScore> scores;
    r.quality.add(
        segmentation::evaluateSegmentation(result.labels, *s.frame.instances, qo, &scores));
    addBreakdown(s, result.labels, scores, &r.per_kind);
    r.object_quality.add(segmentation::evaluateSegmentation(
        objectLabels(s, result.labels, k, all_params), *s.frame.instances, qo));
    for (const auto& [id, score] : scores) {
      KindScore& k = r.per_kind[s.kind.at(id)];
      k.weighted_iou += score.best_iou * double(score.pixels);
      k.weighted_union_iou += score.union_iou * double(score.pixels);
      k.pixels += double(score.pixels);
    }
    auto& t = r.timings;
    t.points_ms += result.timings.filter_ms + result.timings.points_ms;
    t.discontinuity_ms += result.timings.discontinuity_ms;
    t.normals_ms += result.timings.normals_ms;
    t.convexity_ms += result.timings.convexity_ms;
    t.labels_ms += result.timings.labels_ms;
    t.segments_ms += result.timings.segments_ms;
    t.total_ms += result.timings.total_ms;
    ++n;
  }
  auto& t = r.timings;
  for (double* v : {&t.points_ms, &t.discontinuity_ms, &t.normals_ms, &t.convexity_ms,
                    &t.labels_ms, &t.segments_ms, &t.total_ms}) {
    *v /= double(std::max<size_t>(n, 1));
  }
  // Throughput: one segmenter per thread, frames split between them.
  const auto start = std::chrono::steady_clock::now();
  std::vector<std::thread> workers;
  for (int w = 0; w < threads; ++w) {
    workers.emplace_back([&, w] {
      auto seg = segmentation::DepthSegmenter::create(params, k).value();
      for (size_t i = size_t(w); i < samples.size(); i += size_t(threads)) {
        auto res = seg.segment(samples[i].frame.depth);
        (void)res;
      }
    });
  }
  for (auto& w : workers) w.join();
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  r.throughput_fps = double(samples.size()) / s;
  return r;
}

}  // namespace
}  // namespace objdb

int main(int argc, char** argv) {
  using namespace objdb;
  // Keep freed frame buffers in the heap instead of returning them to the kernel: a long-running
  // server reaches this steady state by itself; a short benchmark would otherwise time page
  // faults of fresh memory every frame.
  bench::setUpBenchmarkProcess();
  int per_session = 30, threads = 2;
  std::string cameras = "both";
  Params params;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--frames-per-session" && i + 1 < argc) {
      per_session = std::max(1, std::atoi(argv[++i]));
    } else if (a == "--camera" && i + 1 < argc) {
      cameras = argv[++i];
    } else if (a == "--config" && i + 1 < argc) {
      auto loaded = loadParamsFile(argv[++i]);
      if (!loaded.ok()) {
        std::fprintf(stderr, "segmentation_eval: %s\n", std::string(loaded.status().message()).c_str());
        return 1;
      }
      params = *loaded;
    } else if (a == "--threads" && i + 1 < argc) {
      threads = std::max(1, std::atoi(argv[++i]));
    } else {
      std::fprintf(stderr,
                   "usage: segmentation_eval [--frames-per-session N] [--camera vga|tango|both] "
                   "[--threads N] [--config FILE.json]\n");
      return 2;
    }
  }
  std::vector<std::string> list;
  if (cameras == "both") {
    list = {"vga", "tango"};
  } else {
    list = {cameras};
  }
  std::printf("Depth segmentation on the synthetic lounge (%d frames per session, 3 sessions)\n\n",
              per_session);
  std::printf("%-6s %-6s | %6s %6s %6s %6s %6s %6s | %7s | %7s %9s | %8s %7s %7s %9s | %8s "
              "%7s\n",
              "camera", "noise", "points", "disc", "normal", "convex", "labels", "segs", "total",
              "fps(1)", ("fps(" + std::to_string(threads) + ")").c_str(), "coverage", "under%",
              "seg/obj", "union cov", "obj cov", "obj und%");
  std::vector<std::pair<std::string, std::map<std::string, KindScore>>> per_kind_rows;
  for (const auto& camera : list) {
    const Intrinsics k = intrinsicsPreset(camera).value();
    for (bool noise : {true, false}) {
      const auto samples = renderFrames(camera, noise, per_session);
      const auto r = run(samples, k, threads, params);
      const auto& t = r.timings;
      std::printf(
          "%-6s %-6s | %6.2f %6.2f %6.2f %6.2f %6.2f %6.2f | %7.2f | %7.1f %9.1f | %8.3f %7.2f "
          "%7.2f %9.3f | %8.3f %7.2f\n",
          camera.c_str(), noise ? "yes" : "no", t.points_ms, t.discontinuity_ms, t.normals_ms,
          t.convexity_ms, t.labels_ms, t.segments_ms, t.total_ms, 1000.0 / t.total_ms,
          r.throughput_fps, r.quality.coverage(), 100.0 * r.quality.underSegmentationRate(),
          r.quality.segmentsPerObject(), r.quality.unionCoverage(), r.object_quality.coverage(),
          100.0 * r.object_quality.underSegmentationRate());
      per_kind_rows.push_back({camera + (noise ? " noisy" : " clean"), r.per_kind});
    }
  }
  std::printf("\nCoverage per object kind (size-weighted IoU: best segment / union of the "
              "segments mostly inside the object):\n%-18s", "kind");
  for (const auto& [name, kinds] : per_kind_rows) std::printf(" %15s", name.c_str());
  std::printf("\n");
  if (!per_kind_rows.empty()) {
    for (const auto& [kind, unused] : per_kind_rows.front().second) {
      std::printf("%-18s", kind.c_str());
      for (const auto& [name, kinds] : per_kind_rows) {
        const auto it = kinds.find(kind);
        const bool none = it == kinds.end() || it->second.pixels == 0;
        std::printf("    %5.3f / %5.3f", none ? 0.0 : it->second.weighted_iou / it->second.pixels,
                    none ? 0.0 : it->second.weighted_union_iou / it->second.pixels);
      }
      std::printf("\n");
    }
  }
  std::printf("\nWhere each kind's pixels go, %% of its pixels (no depth / unlabelled / best segment "
              "/ other segments | in frames where no segment has IoU >= 0.1 with it):\n");
  for (const auto& [name, kinds] : per_kind_rows) {
    std::printf("%s\n", name.c_str());
    for (const auto& [kind, k] : kinds) {
      const double n = std::max(k.pixels, 1.0) / 100.0;
      std::printf("  %-18s %5.1f %5.1f %5.1f %5.1f | %5.1f\n", kind.c_str(), k.no_depth / n,
                  k.unlabelled / n, k.in_best / n, k.elsewhere / n, k.lost / n);
    }
  }
  std::printf("\nTimes in ms per frame, one thread, after 5 untimed warm-up frames; fps(N) = "
              "throughput with N segmenters.\n"
              "coverage: size-weighted IoU of each object's best segment (floor/walls excluded);\n"
              "union cov: the same for the union of the segments whose majority is the object\n"
              "(composite objects such as chairs are cut into parts at real concave junctions);\n"
              "under%%: segments with >= 2 instances each > 10 %% of the segment; seg/obj: "
              "segments whose majority is an object, per object;\n"
              "obj cov / obj und%%: coverage and under-segmentation of the frame's segments grouped "
              "into objects as the GSM groups its labels (the frame fused alone at 2 cm).\n");
  return 0;
}
