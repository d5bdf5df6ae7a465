// features_bench: keypoints and descriptors of one object view, measured like the peer figures
// for PCL (1.13 on an ~8.6k-point object view after a 1 cm voxel filter: ISS
// 300 / 176 ms, Harris3D 65 / 41 ms, FPFH r = 10 cm at the keypoints 710 / 403 ms on 1 / 2
// threads). The view is the chair model of bench/chair_model.h (its 1 cm surface cloud); every
// figure is the median of --repeats runs.
//
//   build/bin/features_bench [--repeats 5]
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "bench/bench_util.h"
#include "bench/chair_model.h"
#include "core/model/features.h"

namespace {

using Clock = std::chrono::steady_clock;

template <typename Fn>
double medianMs(int repeats, Fn&& fn) {
  std::vector<double> ms;
  for (int r = 0; r < repeats; ++r) {
    const auto t = Clock::now();
    fn();
    ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - t).count());
  }
  std::sort(ms.begin(), ms.end());
  return ms[ms.size() / 2];
}

}  // namespace

int main(int argc, char** argv) {
  using namespace objdb;
  bench::setUpBenchmarkProcess();
  int repeats = 5;
  for (int i = 1; i < argc; ++i) {
    if (std::string(argv[i]) == "--repeats" && i + 1 < argc) {
      repeats = std::max(1, std::atoi(argv[++i]));
    } else {
      std::fprintf(stderr, "usage: features_bench [--repeats 5]\n");
      return 2;
    }
  }
  auto chair = bench::chairModel(0);
  if (!chair.ok()) {
    std::fprintf(stderr, "features_bench: %s\n", std::string(chair.status().message()).c_str());
    return 1;
  }
  const PointCloud& cloud = chair->cloud;
  const KeypointParams keypoint_params;
  std::vector<uint32_t> keypoints = model::detectKeypoints(cloud, keypoint_params);
  KeypointParams uniform_params;
  uniform_params.uniform_spacing_m = 0.05f;
  const std::vector<uint32_t> uniform = model::detectKeypoints(cloud, uniform_params);

  std::printf("Keypoints and FPFH on a chair view: %zu points (1 cm cloud), %zu ISS ∪ Harris3D "
              "keypoints, %zu with uniform_spacing_m 0.05; median of %d runs\n\n",
              cloud.points.size(), keypoints.size(), uniform.size(), repeats);
  std::printf("%-52s %10s %10s   %s\n", "step", "1 thread", "2 threads", "peer (PCL, 1 / 2)");
  auto row = [&](const char* step, const char* peer, auto&& fn) {
    const double one = medianMs(repeats, [&] { fn(1); });
    const double two = medianMs(repeats, [&] { fn(2); });
    std::printf("%-52s %7.1f ms %7.1f ms   %s\n", step, one, two, peer);
  };
  row("ISS ∪ Harris3D (table I radii, k_min / t_curv filter)", "300 + 65 / 176 + 41 ms",
      [&](int threads) { (void)model::detectKeypoints(cloud, keypoint_params, nullptr, threads); });
  DescriptorParams full;
  full.surface_spacing_m = 0.0f;
  const DescriptorParams resampled;  // the default: histograms over the cloud at 2 cm
  struct FpfhRow {
    const char* step;
    const std::vector<uint32_t>* at;
    const DescriptorParams* params;
    const char* peer;
  };
  for (const FpfhRow& r : {FpfhRow{"FPFH r = 10 cm at those keypoints, over the 1 cm cloud",
                                   &keypoints, &full, "710 / 403 ms"},
                           FpfhRow{"FPFH r = 10 cm at those keypoints, over 2 cm (default)",
                                   &keypoints, &resampled, "710 / 403 ms"},
                           FpfhRow{"FPFH at the uniform keypoints, over the 1 cm cloud", &uniform,
                                   &full, ""},
                           FpfhRow{"FPFH at the uniform keypoints, over 2 cm (default)", &uniform,
                                   &resampled, ""}}) {
    row(r.step, r.peer, [&](int threads) {
      std::vector<uint32_t> k = *r.at;
      (void)model::computeFpfh(cloud, &k, *r.params, threads);
    });
  }
  std::printf("\nPeer view: ~8.6k points; ours: the chair above. Threads: OpenMP inside ISS, "
              "Harris3D (compiled here) and PCL's FPFHEstimationOMP.\n");
  return 0;
}
