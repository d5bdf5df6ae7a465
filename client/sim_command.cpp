// `objdb sim`: writes a synthetic preset (the three-session lounge, the two-session kitchen) or a
// scene file to dataset folders in objdb's layout, with a progress bar and a visibility summary.
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "client/cli_util.h"
#include "client/commands.h"
#include "client/progress.h"
#include "core/io/mesh_io.h"
#include "core/sim/generator.h"
#include "core/sim/kitchen.h"
#include "core/sim/lounge.h"
#include "core/sim/object_library.h"

namespace objdb {
namespace {

constexpr const char* kUsage = R"(usage: objdb sim --preset NAME --out DIR [options]
       objdb sim --scene FILE.json --out DIR [options]
       objdb sim --list
       objdb sim --export-library DIR

Renders a synthetic world into dataset folders in objdb's layout (docs/dataset-format.md):
depth/, color/, instances/ (ground truth), poses.txt, intrinsics.json, objects.json, scene.json.

  --preset NAME        lounge     three sessions, 17 objects of 11 kinds (paper §IV), one folder
                                  per session (DIR/session_1 ..) and DIR/objects.json
                       kitchen    two sessions: fitted kitchen, table, 4 identical chairs, mugs
                       two-boxes  two boxes on a floor, 30 frames
  --scene FILE         a scene file (docs/synthetic-world.md); written to DIR
  --out DIR            output folder
  --camera NAME        vga (640x480) or tango (224x172); default: the preset's (lounge: tango,
                       kitchen: vga)
  --frames N           frames per session (lounge default 300, kitchen 240)
  --seed N             noise seed, kitchen: also the pose drift's (default 1)
  --no-noise           exact depth (no noise, dropouts or quantisation beyond depth_scale)
  --no-drift           kitchen: write the poses the images were rendered from (no pose drift)
  --no-color           skip the colour images
  --threads N          frames rendered in parallel (default 2)
  --overwrite          replace datasets already in DIR
  --list               list presets and object kinds
  --export-library DIR write every library object kind as DIR/<kind>.ply
  -h, --help           this text
)";

struct SimArgs {
  std::string preset, scene_file, out, camera, export_dir;
  int frames = 0;
  uint64_t seed = 1;
  bool seed_set = false, noise = true, drift = true, color = true, overwrite = false, list = false;
  int threads = 2;
};


int usageError(const std::string& message) { return cli::usageError("sim", message, kUsage); }

int reportError(const Status& status) { return cli::reportError("sim", status); }

int runScenes(const std::vector<sim::Scene>& scenes, const std::filesystem::path& out,
              bool multi_session, const SimArgs& args) {
  sim::GenerateOptions options;
  options.write_color = args.color;
  options.overwrite = args.overwrite;
  options.threads = args.threads;
  std::error_code ec;
  std::filesystem::create_directories(out, ec);
  if (ec) return reportError(absl::UnavailableError("cannot create " + out.string() + ": " + ec.message()));
  std::printf("%-12s %7s %8s %9s %11s %10s\n", "session", "frames", "objects", "min vis.",
              "size (MB)", "time (s)");
  for (const auto& scene : scenes) {
    const auto dir = multi_session ? out / scene.name : out;
    cli::ProgressBar bar("rendering " + scene.name, size_t(scene.trajectory.frames));
    auto stats = sim::generateDataset(scene, dir, options,
                                      [&](size_t done, size_t) { bar.update(done); });
    if (!stats.ok()) return reportError(stats.status());
    bar.finish();
    int min_visible = 1 << 30;
    size_t n_objects = 0;
    for (const auto& o : scene.objects) {
      if (o.structure) continue;
      ++n_objects;
      min_visible = std::min(min_visible, stats->frames_visible.at(o.id));
    }
    uintmax_t bytes = 0;
    for (const auto& entry : std::filesystem::recursive_directory_iterator(dir)) {
      if (entry.is_regular_file()) bytes += entry.file_size();
    }
    std::printf("%-12s %7zu %8zu %9d %11.1f %10.1f\n", scene.name.c_str(), stats->frames,
                n_objects, n_objects ? min_visible : 0, double(bytes) / 1e6, stats->seconds);
  }
  if (multi_session) {
    if (Status s = sim::writePresetIndex(out, scenes); !s.ok()) return reportError(s);
  }
  std::printf("written to %s\n", out.string().c_str());
  return 0;
}

}  // namespace

int runSimCommand(int argc, char** argv) {
  SimArgs args;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&](const char* name) -> const char* {
      if (i + 1 >= argc) return nullptr;
      (void)name;
      return argv[++i];
    };
    long long n = 0;
    if (a == "-h" || a == "--help") {
      std::printf("%s", kUsage);
      return 0;
    } else if (a == "--preset" || a == "--scene" || a == "--out" || a == "--camera" ||
               a == "--export-library") {
      const char* v = value(a.c_str());
      if (!v) return usageError(a + " needs a value");
      (a == "--preset" ? args.preset
       : a == "--scene" ? args.scene_file
       : a == "--out"   ? args.out
       : a == "--camera" ? args.camera
                         : args.export_dir) = v;
    } else if (a == "--frames") {
      const char* v = value("--frames");
      if (!v || !cli::parseInt(v, 1, 1000000, &n)) return usageError("--frames needs an integer 1..1000000");
      args.frames = int(n);
    } else if (a == "--seed") {
      const char* v = value("--seed");
      if (!v || !cli::parseInt(v, 0, (1LL << 62), &n)) return usageError("--seed needs a non-negative integer");
      args.seed = uint64_t(n);
      args.seed_set = true;
    } else if (a == "--threads") {
      const char* v = value("--threads");
      if (!v || !cli::parseInt(v, 1, 64, &n)) return usageError("--threads needs an integer 1..64");
      args.threads = int(n);
    } else if (a == "--no-noise") {
      args.noise = false;
    } else if (a == "--no-drift") {
      args.drift = false;
    } else if (a == "--no-color") {
      args.color = false;
    } else if (a == "--overwrite") {
      args.overwrite = true;
    } else if (a == "--list") {
      args.list = true;
    } else {
      return usageError("unknown option '" + a + "'");
    }
  }

  if (args.list) {
    std::printf("presets:");
    for (const auto& p : sim::presetNames()) std::printf(" %s", p.c_str());
    std::printf("\nobject kinds:");
    for (const auto& k : sim::libraryKinds()) std::printf(" %s", k.c_str());
    std::printf("\n");
    return 0;
  }
  if (!args.export_dir.empty()) {
    std::filesystem::create_directories(args.export_dir);
    for (const auto& kind : sim::libraryKinds()) {
      auto mesh = sim::makeLibraryObject(kind);
      if (!mesh.ok()) return reportError(mesh.status());
      const auto path = std::filesystem::path(args.export_dir) / (kind + ".ply");
      if (Status s = io::writePlyMesh(path, *mesh); !s.ok()) return reportError(s);
      std::printf("%-18s %6zu vertices %6zu triangles  -> %s\n", kind.c_str(),
                  mesh->vertices.size(), mesh->triangles.size(), path.string().c_str());
    }
    return 0;
  }
  if (args.preset.empty() == args.scene_file.empty()) {
    return usageError("give exactly one of --preset or --scene");
  }
  if (args.out.empty()) return usageError("--out DIR is required");

  std::vector<sim::Scene> scenes;
  bool multi_session = false;
  if (args.preset == "lounge") {
    sim::LoungeOptions options;
    if (!args.camera.empty()) options.camera = args.camera;
    if (args.frames > 0) options.frames_per_session = args.frames;
    options.seed = args.seed;
    options.noise = args.noise;
    auto lounge = sim::loungePreset(options);
    if (!lounge.ok()) return reportError(lounge.status());
    scenes = std::move(*lounge);
    multi_session = true;
  } else if (args.preset == "kitchen") {
    sim::KitchenOptions options;
    if (!args.camera.empty()) options.camera = args.camera;
    if (args.frames > 0) options.frames_per_session = args.frames;
    options.seed = args.seed;
    options.noise = args.noise;
    options.drift = args.drift;
    auto kitchen = sim::kitchenPreset(options);
    if (!kitchen.ok()) return reportError(kitchen.status());
    scenes = std::move(*kitchen);
    multi_session = true;
  } else if (args.preset == "two-boxes") {
    const std::string camera = args.camera.empty() ? "vga" : args.camera;
    if (auto k = intrinsicsPreset(camera); !k.ok()) return reportError(k.status());
    scenes.push_back(sim::twoBoxesScene(camera, args.frames > 0 ? args.frames : 30));
  } else if (!args.preset.empty()) {
    std::string known;
    for (const auto& p : sim::presetNames()) known += (known.empty() ? "" : ", ") + p;
    return usageError("unknown preset '" + args.preset + "' (known: " + known + ")");
  } else {
    auto scene = sim::loadSceneFile(args.scene_file);
    if (!scene.ok()) return reportError(scene.status());
    if (!args.camera.empty()) {
      auto k = intrinsicsPreset(args.camera);
      if (!k.ok()) return reportError(k.status());
      scene->camera_preset = args.camera;
      scene->intrinsics = *k;
    }
    if (args.frames > 0) scene->trajectory.frames = args.frames;
    scenes.push_back(std::move(*scene));
  }
  for (auto& scene : scenes) {
    if (!args.noise) scene.noise.enabled = false;
    // The multi-session presets seed each session themselves (seed + k).
    if (args.seed_set && !multi_session) scene.noise.seed = args.seed;
  }
  return runScenes(scenes, args.out, multi_session, args);
}

}  // namespace objdb
