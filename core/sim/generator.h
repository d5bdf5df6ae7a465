// Renders a scene along its trajectory into a dataset folder in objdb's layout (depth, colour,
// ground-truth instances, poses, objects.json, and the scene file itself as scene.json), with
// progress reporting and per-object visibility counts.
#pragma once

#include <filesystem>
#include <functional>
#include <map>
#include <vector>

#include "core/common/frame.h"
#include "core/sim/scene.h"

namespace objdb::sim {

struct GenerateOptions {
  bool write_color = true;
  bool overwrite = false;      // replace an existing dataset in the folder
  int threads = 2;             // frames rendered in parallel (output order is kept)
  int min_visible_pixels = 0;  // visibility threshold; 0 → 0.5 % of the image
};

struct GenerateStats {
  size_t frames = 0;
  std::map<int, int> frames_visible;  // object id → frames where it covers ≥ min pixels
  NoiseStats noise;                   // summed over frames
  double seconds = 0.0;
};

// Called after each written frame with (frames done, frames total).
using ProgressFn = std::function<void(size_t, size_t)>;

// Renders frame `index` of a built scene from `T_world_camera` (noise applied, deterministic for
// the scene's seed). The frame's T_world_camera is that pose with the scene's drift
// (driftedPose; the same pose when the scene has none); depth and instances show the true view.
Frame renderFrame(const Scene& scene, const BuiltScene& built, const Renderer& renderer,
                  const Transform& T_world_camera, size_t index, bool with_color,
                  NoiseStats* noise = nullptr);

StatusOr<GenerateStats> generateDataset(const Scene& scene, const std::filesystem::path& out,
                                        const GenerateOptions& options = {},
                                        const ProgressFn& progress = {});

}  // namespace objdb::sim

namespace objdb::sim {

// Writes the index of a multi-session preset: `root`/objects.json listing every object once
// ({"objects": [{"id","category","mesh","structure","sessions": ["session_1", ...]}]}).
Status writePresetIndex(const std::filesystem::path& root, const std::vector<Scene>& sessions);

}  // namespace objdb::sim
