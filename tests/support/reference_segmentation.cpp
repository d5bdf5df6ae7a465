#include "tests/support/reference_segmentation.h"

#include <cmath>
#include <vector>

#include <Eigen/Core>

namespace objdb::testing {

ReferenceLabels referenceLabels(const Image<uint8_t>& boundaries, const DepthImage& depth,
                                const Image<uint8_t>& has_normal, const Intrinsics& k, int min_segment_px, int growth_iterations,
                                float max_growth_distance_m) {
  const int w = boundaries.width, h = boundaries.height;
  ReferenceLabels out;
  out.labels = Image<int32_t>(w, h, 0);
  out.tie = Image<uint8_t>(w, h, 0);
  const int du[4] = {-1, 1, 0, 0}, dv[4] = {0, 0, -1, 1};

  // Connected components by breadth-first search, visited in raster order.
  Image<int32_t> component(w, h, 0);
  int32_t n_components = 0;
  std::vector<std::pair<int, int>> queue;
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      if (boundaries.at(u, v) != 0 || component.at(u, v) != 0) continue;
      const int32_t c = ++n_components;
      queue.assign(1, {u, v});
      component.at(u, v) = c;
      for (size_t q = 0; q < queue.size(); ++q) {
        const auto [qu, qv] = queue[q];
        for (int d = 0; d < 4; ++d) {
          const int nu = qu + du[d], nv = qv + dv[d];
          if (nu < 0 || nv < 0 || nu >= w || nv >= h) continue;
          if (boundaries.at(nu, nv) != 0 || component.at(nu, nv) != 0) continue;
          component.at(nu, nv) = c;
          queue.push_back({nu, nv});
        }
      }
      if (int(queue.size()) >= min_segment_px) {
        const int32_t label = ++out.segments;
        for (const auto& [pu, pv] : queue) out.labels.at(pu, pv) = label;
      } else {
        ++out.dropped_small;
      }
    }
  }

  auto point = [&](int u, int v) {
    const double z = depth.at(u, v);
    return Eigen::Vector3d((u - k.cx) * z / k.fx, (v - k.cy) * z / k.fy, z);
  };
  for (int it = 0; it < growth_iterations; ++it) {
    const Image<int32_t> before = out.labels;
    bool changed = false;
    for (int v = 0; v < h; ++v) {
      for (int u = 0; u < w; ++u) {
        if (before.at(u, v) != 0 || !isValidDepth(depth.at(u, v)) || !has_normal.at(u, v)) continue;
        const Eigen::Vector3d p = point(u, v);
        double gaps[4];
        int32_t best = 0;
        double best_gap = max_growth_distance_m;
        for (int d = 0; d < 4; ++d) {
          const int nu = u + du[d], nv = v + dv[d];
          gaps[d] = -1.0;
          if (nu < 0 || nv < 0 || nu >= w || nv >= h || before.at(nu, nv) == 0) continue;
          gaps[d] = (point(nu, nv) - p).norm();
          if (gaps[d] <= best_gap && (best == 0 || gaps[d] < best_gap)) {
            best_gap = gaps[d];
            best = before.at(nu, nv);
          }
        }
        bool tie = false;
        for (int d = 0; best != 0 && d < 4; ++d) {
          if (gaps[d] < 0.0) continue;
          const int32_t l = before.at(u + du[d], v + dv[d]);
          tie |= l != best && gaps[d] <= best_gap * (1.0 + 1e-5);
        }
        if (best != 0) {
          out.labels.at(u, v) = best;
          out.tie.at(u, v) = tie ? 1 : 0;
          changed = true;
        }
      }
    }
    if (!changed) break;
  }
  return out;
}

}  // namespace objdb::testing
