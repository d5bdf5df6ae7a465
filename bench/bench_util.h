// Shared set-up and ground-truth helpers of the benchmarks (not part of the product).
#pragma once

#include <malloc.h>

#include <cstdint>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "core/common/frame.h"
#include "core/common/intrinsics.h"
#include "core/common/mesh.h"
#include "core/sim/scene.h"

namespace objdb::bench {

// Keeps freed memory in the process (no mmap per large buffer, no trimming): a fresh vector per
// frame otherwise costs page faults that dwarf the work on these VMs. One-thread figures mean
// one thread, OpenCV's pool included.
inline void setUpBenchmarkProcess() {
  mallopt(M_MMAP_THRESHOLD, 256 << 20);
  mallopt(M_TRIM_THRESHOLD, 512 << 20);
  cv::setNumThreads(1);
}

// fn(p_world, instance id) for every pixel of a rendered frame with a valid depth up to
// max_range_m and a ground-truth instance.
template <typename Fn>
void forEachInstancePoint(const Frame& frame, const Intrinsics& k, float max_range_m, Fn&& fn) {
  const Eigen::Isometry3f T = frame.T_world_camera.cast<float>();
  for (int v = 0; v < k.height; ++v) {
    for (int u = 0; u < k.width; ++u) {
      const float z = frame.depth.at(u, v);
      const uint16_t id = frame.instances->at(u, v);
      if (!isValidDepth(z) || id == 0 || z > max_range_m) continue;
      fn(T * Eigen::Vector3f(float((u - k.cx) * z / k.fx), float((v - k.cy) * z / k.fy), z), id);
    }
  }
}

}  // namespace objdb::bench
