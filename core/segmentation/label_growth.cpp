#include "core/segmentation/label_growth.h"

#include <algorithm>
#include <limits>

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

// nearestNeighbourLabel for a pixel off the image border (all four neighbours exist).
OBJDB_INLINE_KERNEL int32_t nearestInteriorLabel(const float* D, const int32_t* labels,
                                                 const float* ru, const float* ry, size_t ws,
                                                 PixelAt p, float max_d2) {
  const float z = D[p.i], rx = ru[p.u], rv = ry[p.v], x = rx * z, y = rv * z;
  const size_t j[4] = {p.i - 1, p.i + 1, p.i - ws, p.i + ws};
  const float jx[4] = {ru[p.u - 1], ru[p.u + 1], rx, rx};
  const float jy[4] = {rv, rv, ry[p.v - 1], ry[p.v + 1]};
  int32_t best = 0;
  float best_d2 = max_d2;
  // Chained selects on values (a bool & bool compiles to branches, and they mispredict).
  for (int d = 0; d < 4; ++d) {
    const int32_t l = labels[j[d]];
    const float zj = D[j[d]];
    const float dx = jx[d] * zj - x, dy = jy[d] * zj - y, dz = zj - z;
    float d2 = dx * dx + dy * dy + dz * dz;
    d2 = l != 0 ? d2 : std::numeric_limits<float>::infinity();
    const bool take = d2 <= best_d2;
    best_d2 = take ? d2 : best_d2;
    best = take ? l : best;
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
  thread_local std::vector<uint8_t> growable_storage, open_storage;
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
    // Branch-free: every pixel is written to the next slot, which is kept when it changed.
    size_t count = changed.size();
    changed.resize(count + ws);
    for (int u = 0; u < w; ++u) {
      changed[count] = {uint32_t(row + size_t(u)), uint16_t(u), uint16_t(v)};
      count += L[row + size_t(u)] != prev[row + size_t(u)] ? 1 : 0;
    }
    changed.resize(count);
  }

  // Later rings: the unlabelled growable neighbours of the last ring, against the labels so far.
  // `open` (padded by one pixel of 0 on every side, so that a neighbour needs no bounds test)
  // marks the growable pixels without a label that are not queued yet: one byte to test.
  const size_t pw = ws + 2;
  open_storage.assign(pw * size_t(h + 2), 0);
  uint8_t* __restrict open = open_storage.data();
  // Growable pixels had no label before ring 1: open = growable minus ring 1's pixels.
  for (int v = 0; v < h; ++v) {
    std::copy(growable + size_t(v) * ws, growable + size_t(v + 1) * ws,
              open + size_t(v + 1) * pw + 1);
  }
  for (const PixelAt p : changed) open[size_t(p.v + 1) * pw + size_t(p.u + 1)] = 0;
  const ptrdiff_t step[4] = {-1, 1, -ptrdiff_t(pw), ptrdiff_t(pw)};
  const int step_u[4] = {-1, 1, 0, 0}, step_v[4] = {0, 0, -1, 1};
  const ptrdiff_t step_i[4] = {-1, 1, -ptrdiff_t(ws), ptrdiff_t(ws)};
  for (int it = 1; it < iterations && !changed.empty(); ++it) {
    // Branch-free as in ring 1 (whether a neighbour is open is unpredictable).
    candidates.resize(4 * changed.size());
    size_t count = 0;
    for (const PixelAt p : changed) {
      const size_t padded = size_t(p.v + 1) * pw + size_t(p.u + 1);
      for (int d = 0; d < 4; ++d) {
        uint8_t& o = open[ptrdiff_t(padded) + step[d]];
        const int u = p.u + step_u[d], v = p.v + step_v[d];
        candidates[count] = {uint32_t(ptrdiff_t(p.i) + step_i[d]), uint16_t(u), uint16_t(v)};
        count += o;
        o = 0;
      }
    }
    candidates.resize(count);
    new_labels.resize(count);
    for (size_t c = 0; c < count; ++c) {
      const PixelAt q = candidates[c];
      new_labels[c] = (q.u > 0) & (q.v > 0) & (int(q.u) + 1 < w) & (int(q.v) + 1 < h)
                          ? nearestInteriorLabel(D, L, ru, ry, ws, q, max_d2)
                          : nearestNeighbourLabel(D, L, ru, ry, w, h, q, max_d2);
    }
    changed.resize(count);
    size_t grown = 0;
    for (size_t c = 0; c < count; ++c) {
      const PixelAt q = candidates[c];
      const int32_t label = new_labels[c];
      L[q.i] = label;  // 0 before
      open[size_t(q.v + 1) * pw + size_t(q.u + 1)] = label == 0 ? 1 : 0;  // may grow later
      changed[grown] = q;
      grown += label != 0 ? 1 : 0;
    }
    changed.resize(grown);
  }
}

}  // namespace objdb::segmentation
