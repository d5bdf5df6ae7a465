#include "core/segmentation/label_growth.h"

#include <algorithm>

#include "core/common/simd.h"

namespace objdb::segmentation {
namespace {

// One pass of label growth over row v of the interior columns [1, w − 1): each growable pixel
// without a label takes the label of its nearest labelled 4-neighbour (left, right, up, down;
// the later one on a tie) in `prev` whose point lies within sqrt(max_d2), writing `out`.
// Points are recomputed from depth exactly as depthToPoints does (ru[u] · z, ry · z, z). Every
// load unconditional, then selects: the loop vectorises. Returns whether a label changed.
OBJDB_INLINE_KERNEL bool growRowInterior(const float* __restrict D, const int32_t* __restrict prev,
                                         const uint8_t* __restrict growable,
                                         const float* __restrict ru, float ry, float ry_up,
                                         float ry_down, size_t row, int w, float max_d2,
                                         int32_t* __restrict out) {
  const size_t ws = size_t(w);
  const float* __restrict dc = D + row;
  const float* __restrict du = dc - ws;
  const float* __restrict dd = dc + ws;
  const int32_t* __restrict lc = prev + row;
  const int32_t* __restrict lu = lc - ws;
  const int32_t* __restrict ld = lc + ws;
  const uint8_t* __restrict g = growable + row;
  int32_t* __restrict o = out + row;
  int32_t changed = 0;
  for (size_t u = 1; u + 1 < ws; ++u) {
    const float z = dc[u];
    const float x = ru[u] * z, y = ry * z;
    int32_t best = 0;
    float best_d2 = max_d2;
    // Left, right, up, down; the later one wins a tie.
    float ex = ru[u - 1] * dc[u - 1] - x, ey = ry * dc[u - 1] - y, ez = dc[u - 1] - z;
    float d2 = ex * ex + ey * ey + ez * ez;
    bool take = (lc[u - 1] != 0) & (d2 <= best_d2);
    best_d2 = take ? d2 : best_d2;
    best = take ? lc[u - 1] : best;
    ex = ru[u + 1] * dc[u + 1] - x, ey = ry * dc[u + 1] - y, ez = dc[u + 1] - z;
    d2 = ex * ex + ey * ey + ez * ez;
    take = (lc[u + 1] != 0) & (d2 <= best_d2);
    best_d2 = take ? d2 : best_d2;
    best = take ? lc[u + 1] : best;
    ex = ru[u] * du[u] - x, ey = ry_up * du[u] - y, ez = du[u] - z;
    d2 = ex * ex + ey * ey + ez * ez;
    take = (lu[u] != 0) & (d2 <= best_d2);
    best_d2 = take ? d2 : best_d2;
    best = take ? lu[u] : best;
    ex = ru[u] * dd[u] - x, ey = ry_down * dd[u] - y, ez = dd[u] - z;
    d2 = ex * ex + ey * ey + ez * ez;
    take = (ld[u] != 0) & (d2 <= best_d2);
    best = take ? ld[u] : best;
    const int32_t old = lc[u];
    const int32_t grow = int32_t(g[u] != 0) & int32_t(old == 0);
    const int32_t label = grow != 0 ? best : old;
    o[u] = label;
    changed |= label ^ old;
  }
  return changed != 0;
}

// A pixel and its coordinates (no division to find its neighbours).
struct PixelAt {
  uint32_t i;
  uint16_t u, v;
};

// The label a pixel anywhere takes from `labels` (see growRowInterior), 0 for none; neighbours
// outside the image do not count.
OBJDB_INLINE_KERNEL int32_t nearestNeighbourLabel(const float* D, const int32_t* labels,
                                                  const float* ru, const float* ry, int w, int h,
                                                  PixelAt p, float max_d2) {
  const int u = p.u, v = p.v;
  const float z = D[p.i], x = ru[u] * z, y = ry[v] * z;
  const int nu[4] = {u - 1, u + 1, u, u}, nv[4] = {v, v, v - 1, v + 1};
  int32_t best = 0;
  float best_d2 = max_d2;
  for (int d = 0; d < 4; ++d) {
    if (nu[d] < 0 || nv[d] < 0 || nu[d] >= w || nv[d] >= h) continue;
    const size_t j = size_t(nv[d]) * size_t(w) + size_t(nu[d]);
    if (labels[j] == 0) continue;
    const float zj = D[j];
    const float dx = ru[nu[d]] * zj - x, dy = ry[nv[d]] * zj - y, dz = zj - z;
    const float d2 = dx * dx + dy * dy + dz * dz;
    if (d2 <= best_d2) {
      best_d2 = d2;
      best = labels[j];
    }
  }
  return best;
}

}  // namespace

OBJDB_VECTOR_CLONES
void growLabels(const DepthImage& depth, const Planar3f& normals, const Intrinsics& k,
                int iterations, float max_distance, LabelImage* labels) {
  const int w = depth.width, h = depth.height;
  const size_t n = size_t(w) * size_t(h), ws = size_t(w);
  if (w < 3 || h < 3 || iterations <= 0) return;
  thread_local std::vector<uint8_t> growable_storage, queued_storage;
  thread_local std::vector<int32_t> prev_storage;
  thread_local std::vector<float> ru_storage, ry_storage;
  thread_local std::vector<PixelAt> changed, candidates;
  thread_local std::vector<int32_t> new_labels;
  growable_storage.resize(n);
  ru_storage.resize(ws);
  ry_storage.resize(size_t(h));
  uint8_t* __restrict growable = growable_storage.data();
  float* __restrict ru = ru_storage.data();
  float* __restrict ry = ry_storage.data();
  int32_t* __restrict L = labels->data.data();
  const float* __restrict D = depth.data.data();
  {
    const float* __restrict nx = normals.x.data();
    const float* __restrict ny = normals.y.data();
    const float* __restrict nz = normals.z.data();
    for (size_t i = 0; i < n; ++i) {
      const bool normal = (nx[i] != 0.0f) | (ny[i] != 0.0f) | (nz[i] != 0.0f);
      growable[i] = uint8_t((L[i] == 0) & (D[i] > 0.0f) & normal);
    }
  }
  const float fx_inv = float(1.0 / k.fx), fy_inv = float(1.0 / k.fy);
  for (int u = 0; u < w; ++u) ru[u] = (float(u) - float(k.cx)) * fx_inv;
  for (int v = 0; v < h; ++v) ry[v] = (float(v) - float(k.cy)) * fy_inv;
  const float max_d2 = max_distance * max_distance;

  // Ring 1: every growable pixel against the labels of the components.
  prev_storage.assign(L, L + n);
  const int32_t* __restrict prev = prev_storage.data();
  changed.clear();
  auto grow_border_pixel = [&](int u, int v) {
    const size_t i = size_t(v) * ws + size_t(u);
    if (!growable[i]) return;
    L[i] = nearestNeighbourLabel(D, prev, ru, ry, w, h, {uint32_t(i), uint16_t(u), uint16_t(v)},
                                 max_d2);
  };
  for (int v = 0; v < h; ++v) {
    const size_t row = size_t(v) * ws;
    if (v == 0 || v + 1 == h) {
      for (int u = 0; u < w; ++u) grow_border_pixel(u, v);
    } else {
      grow_border_pixel(0, v);
      const bool any =
          growRowInterior(D, prev, growable, ru, ry[v], ry[v - 1], ry[v + 1], row, w, max_d2, L);
      grow_border_pixel(w - 1, v);
      if (!any && L[row] == prev[row] && L[row + ws - 1] == prev[row + ws - 1]) continue;
    }
    for (int u = 0; u < w; ++u) {
      if (L[row + size_t(u)] != prev[row + size_t(u)]) {
        changed.push_back({uint32_t(row + size_t(u)), uint16_t(u), uint16_t(v)});
      }
    }
  }

  // Later rings: the unlabelled growable neighbours of the last ring, against the labels so far.
  queued_storage.resize(n);
  uint8_t* __restrict queued = queued_storage.data();  // all 0 between calls
  for (int it = 1; it < iterations && !changed.empty(); ++it) {
    candidates.clear();
    for (const PixelAt p : changed) {
      const int nu[4] = {p.u - 1, p.u + 1, p.u, p.u}, nv[4] = {p.v, p.v, p.v - 1, p.v + 1};
      for (int d = 0; d < 4; ++d) {
        if (nu[d] < 0 || nv[d] < 0 || nu[d] >= w || nv[d] >= h) continue;
        const size_t j = size_t(nv[d]) * ws + size_t(nu[d]);
        if (growable[j] & (L[j] == 0) & (queued[j] == 0)) {
          queued[j] = 1;
          candidates.push_back({uint32_t(j), uint16_t(nu[d]), uint16_t(nv[d])});
        }
      }
    }
    new_labels.resize(candidates.size());
    for (size_t c = 0; c < candidates.size(); ++c) {
      new_labels[c] = nearestNeighbourLabel(D, L, ru, ry, w, h, candidates[c], max_d2);
    }
    changed.clear();
    for (size_t c = 0; c < candidates.size(); ++c) {
      queued[candidates[c].i] = 0;
      if (new_labels[c] != 0) {
        L[candidates[c].i] = new_labels[c];
        changed.push_back(candidates[c]);
      }
    }
  }
}

}  // namespace objdb::segmentation
