// Synthetic-world speed: rendering (z-buffer), noise and whole frames of the lounge at VGA and
// Tango resolution, one thread. Target: a VGA frame in well under 50 ms.
#include <benchmark/benchmark.h>

#include "core/sim/generator.h"
#include "core/sim/lounge.h"

namespace objdb::sim {
namespace {

struct LoungeFixture {
  Scene scene;
  BuiltScene built;
  std::vector<Transform> poses;
  explicit LoungeFixture(const std::string& camera) {
    LoungeOptions options;
    options.camera = camera;
    scene = loungePreset(options).value()[0];
    built = buildScene(scene).value();
    poses = sampleTrajectory(scene.trajectory).value();
  }
};

void BM_Render(benchmark::State& state, const std::string& camera, bool color) {
  const LoungeFixture f(camera);
  RenderParams params;
  params.render_color = color;
  const Renderer renderer(f.scene.intrinsics, params);
  RenderOutput out;
  size_t i = 0;
  for (auto _ : state) {
    renderer.render(f.built.instances, f.poses[i++ % f.poses.size()], &out);
    benchmark::DoNotOptimize(out.depth.data.data());
  }
  state.SetLabel(camera);
}

void BM_Noise(benchmark::State& state, const std::string& camera) {
  const LoungeFixture f(camera);
  const Renderer renderer(f.scene.intrinsics);
  RenderOutput out;
  renderer.render(f.built.instances, f.poses[f.poses.size() / 3], &out);
  size_t frame = 0;
  for (auto _ : state) {
    DepthImage depth = out.depth;
    applyDepthNoise(f.scene.noise, frame++, out.cos_incidence, &depth);
    benchmark::DoNotOptimize(depth.data.data());
  }
  state.SetLabel(camera);
}

void BM_Frame(benchmark::State& state, const std::string& camera) {
  const LoungeFixture f(camera);
  const Renderer renderer(f.scene.intrinsics);
  size_t i = 0;
  for (auto _ : state) {
    Frame frame = renderFrame(f.scene, f.built, renderer, f.poses[i % f.poses.size()], i, true);
    ++i;
    benchmark::DoNotOptimize(frame.depth.data.data());
  }
  state.SetLabel(camera);
}

BENCHMARK_CAPTURE(BM_Render, vga_depth_only, std::string("vga"), false)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Render, vga_with_color, std::string("vga"), true)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Render, tango_with_color, std::string("tango"), true)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Noise, vga, std::string("vga"))->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Frame, vga, std::string("vga"))->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Frame, tango, std::string("tango"))->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace objdb::sim
