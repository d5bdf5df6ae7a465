#include "core/sim/generator.h"

#include <chrono>
#include <fstream>
#include <future>
#include <algorithm>
#include <thread>

#include "core/common/logging.h"
#include "core/io/objdb_dataset.h"

#include <nlohmann/json.hpp>

namespace objdb::sim {

Frame renderFrame(const Scene& scene, const BuiltScene& built, const Renderer& renderer,
                  const Transform& T_world_camera, size_t index, bool with_color,
                  NoiseStats* noise) {
  RenderOutput out;
  renderer.render(built.instances, T_world_camera, &out);
  const NoiseStats stats = applyDepthNoise(scene.noise, index, out.cos_incidence, &out.depth);
  if (noise) *noise = stats;
  Frame frame;
  frame.index = index;
  frame.timestamp = double(index) / scene.trajectory.fps;
  // The image is rendered from the true pose; the frame reports the pose a drifting tracker
  // would (identical unless the scene has a drift), as poses.txt does for real recordings.
  frame.T_world_camera =
      driftedPose(scene.drift, T_world_camera, index, size_t(scene.trajectory.frames));
  frame.depth = std::move(out.depth);
  if (with_color) frame.color = std::move(out.color);
  frame.instances = std::move(out.instances);
  return frame;
}

StatusOr<GenerateStats> generateDataset(const Scene& scene, const std::filesystem::path& out,
                                        const GenerateOptions& options,
                                        const ProgressFn& progress) {
  const auto start = std::chrono::steady_clock::now();
  OBJDB_RETURN_IF_ERROR(scene.validate());
  OBJDB_ASSIGN_OR_RETURN(BuiltScene built, buildScene(scene));
  OBJDB_ASSIGN_OR_RETURN(std::vector<Transform> poses, sampleTrajectory(scene.trajectory));
  OBJDB_ASSIGN_OR_RETURN(auto writer, io::ObjdbDatasetWriter::create(
                                          out, scene.intrinsics, scene.depth_scale_m,
                                          options.overwrite));
  RenderParams render_params;
  render_params.render_color = options.write_color;
  const Renderer renderer(scene.intrinsics, render_params);
  const int min_pixels = options.min_visible_pixels > 0
                             ? options.min_visible_pixels
                             : std::max(1, scene.intrinsics.width * scene.intrinsics.height / 200);

  GenerateStats stats;
  for (const auto& o : scene.objects) stats.frames_visible[o.id] = 0;
  const size_t n = poses.size();
  const size_t batch = size_t(std::max(1, options.threads));
  std::vector<Frame> frames(batch);
  std::vector<NoiseStats> noise(batch);
  for (size_t first = 0; first < n; first += batch) {
    const size_t count = std::min(batch, n - first);
    std::vector<std::future<void>> jobs;
    for (size_t k = 0; k < count; ++k) {
      jobs.push_back(std::async(std::launch::async, [&, k] {
        frames[k] = renderFrame(scene, built, renderer, poses[first + k], first + k,
                                options.write_color, &noise[k]);
      }));
    }
    for (auto& job : jobs) job.get();
    for (size_t k = 0; k < count; ++k) {
      std::map<int, int> pixels;
      for (uint16_t id : frames[k].instances->data) {
        if (id != 0) ++pixels[id];
      }
      for (const auto& [id, count_px] : pixels) {
        if (count_px >= min_pixels) ++stats.frames_visible[id];
      }
      stats.noise.out_of_range += noise[k].out_of_range;
      stats.noise.grazing_dropouts += noise[k].grazing_dropouts;
      stats.noise.edge_dropouts += noise[k].edge_dropouts;
      OBJDB_RETURN_IF_ERROR(writer->addFrame(frames[k]));
      ++stats.frames;
      if (progress) progress(stats.frames, n);
    }
  }

  std::vector<io::GroundTruthObject> objects;
  for (const auto& o : scene.objects) {
    objects.push_back(io::GroundTruthObject{o.id, o.category, o.mesh, o.T_world_object, o.structure});
  }
  OBJDB_RETURN_IF_ERROR(writer->finish(objects));
  {
    std::ofstream scene_file(out / "scene.json");
    scene_file << sceneToJson(scene) << "\n";
    if (!scene_file) {
      return absl::UnavailableError(absl::StrCat("cannot write ", (out / "scene.json").string()));
    }
  }
  stats.seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  logger("sim")->debug("generated {} frames of '{}' into {} in {:.1f} s", stats.frames, scene.name,
                       out.string(), stats.seconds);
  return stats;
}

}  // namespace objdb::sim

namespace objdb::sim {

Status writePresetIndex(const std::filesystem::path& root, const std::vector<Scene>& sessions) {
  nlohmann::json objects = nlohmann::json::array();
  std::map<int, size_t> index_of_id;
  for (const auto& scene : sessions) {
    for (const auto& o : scene.objects) {
      auto it = index_of_id.find(o.id);
      if (it == index_of_id.end()) {
        it = index_of_id.emplace(o.id, objects.size()).first;
        objects.push_back({{"id", o.id},
                           {"category", o.category},
                           {"mesh", o.mesh},
                           {"structure", o.structure},
                           {"sessions", nlohmann::json::array()}});
      }
      objects[it->second]["sessions"].push_back(scene.name);
    }
  }
  std::sort(objects.begin(), objects.end(),
            [](const auto& a, const auto& b) { return a["id"] < b["id"]; });
  const auto path = root / "objects.json";
  std::ofstream out(path);
  out << nlohmann::json{{"objects", objects}}.dump(2) << "\n";
  if (!out) return absl::UnavailableError(absl::StrCat("cannot write ", path.string()));
  return absl::OkStatus();
}

}  // namespace objdb::sim
