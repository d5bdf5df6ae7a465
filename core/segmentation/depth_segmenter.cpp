#include "core/segmentation/depth_segmenter.h"

#include "core/common/simd.h"
#include "core/segmentation/label_growth.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

namespace objdb::segmentation {
namespace {

using Clock = std::chrono::steady_clock;
double msSince(Clock::time_point t) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

constexpr int kVgaWidth = 640;
constexpr int kMinNormalWindow = 9;

// Scales a window given for VGA to `width`, keeping it odd and ≥ 3.
int scaledWindow(int vga_window, int width) {
  const int w = static_cast<int>(std::lround(double(vga_window) * width / kVgaWidth));
  return std::max(3, w | 1);
}

// The normal window W is split into a box filter of about W/3 (noise, same-surface neighbours
// only) and central differences W/3 pixels apart (baseline): the footprint stays W wide.
int smoothingWindow(int normal_window) { return std::max(1, (normal_window / 3) | 1); }
int differenceOffset(int normal_window) { return std::max(1, normal_window / 3); }

template <typename T>
void resize(Image<T>* image, int w, int h, T fill) {
  if (image->width != w || image->height != h) *image = Image<T>(w, h, fill);
}

}  // namespace

namespace {

// The depth when it is a measurement (positive and finite), else 0: NaN and −inf fail d > 0,
// +inf fails d < inf. Chained selects on values, so that the loops using it vectorise.
OBJDB_INLINE_KERNEL float measuredOrZero(float d) {
  const float positive = d > 0.0f ? d : 0.0f;
  return positive < std::numeric_limits<float>::infinity() ? positive : 0.0f;
}

// out = the measured depths of `in`, 0 where NaN, ±inf or ≤ 0 (chained selects: vectorises).
OBJDB_VECTOR_CLONES
void sanitiseDepth(const float* __restrict in, size_t n, float* __restrict out) {
  for (size_t i = 0; i < n; ++i) {
    out[i] = measuredOrZero(in[i]);
  }
}

// One pass of hole filling over the interior of row v: out = the row of `in` (measured depths,
// 0 elsewhere), except that an unmeasured pixel with ≥ 5 measured 3 × 3 neighbours whose depths
// spread ≤ `spread` · their minimum takes their mean; other unmeasured pixels keep `keep`'s value.
// The taps are summed in the same row-major order as a scalar loop would: bit-identical.
// Returns the number of pixels filled.
OBJDB_INLINE_KERNEL int fillRow(const float* __restrict in, const float* __restrict keep,
                                float* __restrict out, size_t row, int w, float spread) {
  const size_t ws = size_t(w);
  const float* __restrict a = in + row - ws;
  const float* __restrict b = in + row;
  const float* __restrict c = in + row + ws;
  const float* __restrict k = keep + row;
  float* __restrict o = out + row;
  int filled = 0;
  for (size_t u = 1; u + 1 < ws; ++u) {
    float sum = 0.0f, lo = std::numeric_limits<float>::max(), hi = 0.0f, n = 0.0f;
    const auto tap = [&](float t) {
      const bool m = t > 0.0f;
      sum += m ? t : 0.0f;
      n += m ? 1.0f : 0.0f;
      lo = m & (t < lo) ? t : lo;  // values, not std::min's references: no branch
      hi = t > hi ? t : hi;
    };
    tap(a[u - 1]), tap(a[u]), tap(a[u + 1]);
    tap(b[u - 1]), tap(b[u]), tap(b[u + 1]);
    tap(c[u - 1]), tap(c[u]), tap(c[u + 1]);
    const bool fill = (b[u] == 0.0f) & (n >= 5.0f) & (hi - lo <= spread * lo);
    const float mean = sum / (n > 1.0f ? n : 1.0f);
    o[u] = fill ? mean : (b[u] > 0.0f ? b[u] : k[u]);
    filled += fill ? 1 : 0;
  }
  return filled;
}

// Hole filling on `clean` (measured depths, 0 elsewhere) in place, up to `iterations` passes;
// unmeasured pixels that stay unfilled take `keep`'s value in the last pass (null: `clean`'s).
// `scratch` is reused between calls.
OBJDB_VECTOR_CLONES
size_t fillHoles(float* clean, const float* keep, int w, int h, int iterations, float spread,
                 std::vector<float>* scratch) {
  if (w < 3 || h < 3) return 0;
  const size_t n = size_t(w) * size_t(h), ws = size_t(w);
  scratch->resize(n);
  size_t filled = 0;
  for (int it = 0; it < iterations; ++it) {
    float* out = scratch->data();
    std::copy(clean, clean + ws, out);
    std::copy(clean + n - ws, clean + n, out + n - ws);
    int filled_now = 0;
    for (int v = 1; v + 1 < h; ++v) {
      const size_t row = size_t(v) * ws;
      out[row] = clean[row];
      out[row + ws - 1] = clean[row + ws - 1];
      filled_now += fillRow(clean, clean, out, row, w, spread);
    }
    if (filled_now == 0) break;
    filled += size_t(filled_now);
    std::copy(out, out + n, clean);
  }
  if (keep != nullptr) {
    for (size_t i = 0; i < n; ++i) clean[i] = clean[i] > 0.0f ? clean[i] : keep[i];
  }
  return filled;
}

}  // namespace

size_t fillDepthHoles(DepthImage* depth, int iterations, float max_relative_spread) {
  const size_t n = depth->data.size();
  std::vector<float> clean(n), scratch;
  sanitiseDepth(depth->data.data(), n, clean.data());
  const size_t filled = fillHoles(clean.data(), depth->data.data(), depth->width, depth->height,
                                  iterations, max_relative_spread, &scratch);
  depth->data.swap(clean);
  return filled;
}

OBJDB_VECTOR_CLONES
void depthToPoints(const DepthImage& depth, const Intrinsics& k, PointImage* points) {
  const int w = depth.width, h = depth.height;
  resize(points, w, h, Eigen::Vector3f::Zero().eval());
  const float fx_inv = float(1.0 / k.fx), fy_inv = float(1.0 / k.fy);
  const float cx = float(k.cx), cy = float(k.cy);
  for (int v = 0; v < h; ++v) {
    const float ry = (float(v) - cy) * fy_inv;
    const float* d_row = &depth.data[size_t(v) * w];
    Eigen::Vector3f* p_row = &points->data[size_t(v) * w];
    for (int u = 0; u < w; ++u) {
      const float z = d_row[u];
      if (isValidDepth(z)) {
        p_row[u] = Eigen::Vector3f((float(u) - cx) * fx_inv * z, ry * z, z);
      } else {
        p_row[u].setZero();
      }
    }
  }
}

// Largest jump to a measured neighbour = max(max_window(d) − d, d − min_window(d)), holes
// excluded from both (0 never wins a max, +inf never wins a min): holes are not edges. The
// window's max and min are separable and exact: down the columns into a row buffer padded by
// the radius (so that the row taps need no bounds), then along it.
OBJDB_VECTOR_CLONES
void discontinuityMap(const DepthImage& depth, int window, float threshold, MaskImage* edges) {
  const int w = depth.width, h = depth.height, r = std::max(0, window / 2);
  resize(edges, w, h, uint8_t{0});
  const float kInf = std::numeric_limits<float>::infinity();
  const size_t ws = size_t(w), padded = ws + 2 * size_t(r);
  thread_local std::vector<float> col_hi, col_lo, row_hi, row_lo;
  col_hi.assign(padded, 0.0f);
  col_lo.assign(padded, kInf);
  row_hi.resize(ws);
  row_lo.resize(ws);
  const float* __restrict d = depth.data.data();
  for (int v = 0; v < h; ++v) {
    float* __restrict chi = col_hi.data() + r;
    float* __restrict clo = col_lo.data() + r;
    std::fill(chi, chi + ws, 0.0f);
    std::fill(clo, clo + ws, kInf);
    for (int k = std::max(0, v - r); k <= std::min(h - 1, v + r); ++k) {
      const float* __restrict row = d + size_t(k) * ws;
      for (size_t u = 0; u < ws; ++u) {
        const float t = measuredOrZero(row[u]);
        chi[u] = std::max(chi[u], t);
        clo[u] = std::min(clo[u], t > 0.0f ? t : kInf);
      }
    }
    float* __restrict rhi = row_hi.data();
    float* __restrict rlo = row_lo.data();
    std::copy(chi - r, chi - r + ws, rhi);
    std::copy(clo - r, clo - r + ws, rlo);
    for (int t = 1 - r; t <= r; ++t) {
      const float* __restrict shi = chi + t;
      const float* __restrict slo = clo + t;
      for (size_t u = 0; u < ws; ++u) {
        rhi[u] = std::max(rhi[u], shi[u]);
        rlo[u] = std::min(rlo[u], slo[u]);
      }
    }
    const float* __restrict zr = d + size_t(v) * ws;
    for (size_t u = 0; u < ws; ++u) {  // the edge flag as 0 / 1 in rhi, then packed to bytes
      const float z = measuredOrZero(zr[u]);
      const float jump = std::max(rhi[u] - z, z - rlo[u]);
      const float flag = jump > threshold * z ? 1.0f : 0.0f;
      rhi[u] = z > 0.0f ? flag : 0.0f;
    }
    uint8_t* __restrict e = edges->data.data() + size_t(v) * ws;
    for (size_t u = 0; u < ws; ++u) e[u] = uint8_t(rhi[u]);
  }
}

namespace {

// 1 when a neighbour at depth zj is measured and on the surface of a pixel at depth z, else 0
// (branch-free).
inline float sameSurfaceMask(float zj, float z, float max_relative_distance) {
  const float near = std::abs(zj - z) <= max_relative_distance * z ? 1.0f : 0.0f;
  return zj > 0.0f ? near : 0.0f;
}

// o += mask · (x, y, z, n) over `count` pixels, where mask says whether the neighbour (depth zk)
// is on the centre pixel's surface (depth zc); n = 1 when `nk` is null. Restrict pointers and
// one flat loop: it vectorises.
OBJDB_INLINE_KERNEL void accumulateSameSurface(const float* __restrict zc,
                                              const float* __restrict zk,
                           const float* __restrict xk, const float* __restrict yk,
                           const float* __restrict vk, const float* __restrict nk, int count,
                           float max_relative_distance, float* __restrict ox,
                           float* __restrict oy, float* __restrict oz, float* __restrict on) {
  if (nk == nullptr) {
    for (int u = 0; u < count; ++u) {
      const float m = sameSurfaceMask(zk[u], zc[u], max_relative_distance);
      ox[u] += m * xk[u];
      oy[u] += m * yk[u];
      oz[u] += m * vk[u];
      on[u] += m;
    }
  } else {
    for (int u = 0; u < count; ++u) {
      const float m = sameSurfaceMask(zk[u], zc[u], max_relative_distance);
      ox[u] += m * xk[u];
      oy[u] += m * yk[u];
      oz[u] += m * vk[u];
      on[u] += m * nk[u];
    }
  }
}

// The smoothed points of one row from its window sums: the sums over their counts, zero where
// the pixel is unmeasured (the pixel itself is always in its sum, so the count is ≥ 1 there).
OBJDB_INLINE_KERNEL void normaliseSums(const float* __restrict zc, const float* __restrict ax,
                                       const float* __restrict ay, const float* __restrict az,
                                       const float* __restrict ac, int count,
                                       float* __restrict ox, float* __restrict oy,
                                       float* __restrict oz) {
  for (int u = 0; u < count; ++u) {
    const float scale = 1.0f / (ac[u] > 1.0f ? ac[u] : 1.0f);
    const float z = zc[u];
    ox[u] = z > 0.0f ? ax[u] * scale : 0.0f;
    oy[u] = z > 0.0f ? ay[u] * scale : 0.0f;
    oz[u] = z > 0.0f ? az[u] * scale : 0.0f;
  }
}

// Edge-preserving box filter of the points, as planes: smoothed(u, v) = mean of the valid points
// of the window that lie on the pixel's surface (|Δz| ≤ `max_relative_distance` · z), zero where
// the pixel is unmeasured. A plain box filter would average a silhouette's foreground with the
// background behind it and bend the normals of a band of pixels on both sides into a fake
// concave rim. Separable: along the rows, the window's points on the pixel's surface are summed;
// down the columns, the row sums of the pixels on the pixel's surface. A diagonal neighbour
// across a jump is excluded too: the row sum it belongs to is either of a pixel across the jump
// (left out) or of a pixel on this surface, which left it out — for jumps above about twice the
// threshold (the test is relative to each centre pixel, so it is not transitive below that). Direct sums over the window
// (2 × 5 taps at VGA), every loop branch-free so that it vectorises. Streamed: the row sums of
// the last `window` rows live in a ring buffer that stays in cache, and each output row is
// summed down the columns as soon as its last input row is in. `px`, `py`, `pz` are the points
// as planes (pz = 0 where unmeasured).
OBJDB_VECTOR_CLONES
void smoothPlanes(const float* __restrict px, const float* __restrict py,
                  const float* __restrict pz, int w, int h, int window,
                  float max_relative_distance, Planar3f* smoothed) {
  const int r = window / 2, rows_kept = 2 * r + 1;
  const size_t n = size_t(w) * size_t(h), ws = size_t(w);
  smoothed->resize(n);
  thread_local std::vector<float> ring, acc;
  ring.resize(4 * ws * size_t(rows_kept));
  acc.resize(4 * ws);
  // Ring slot of input row k: sums of x, y, z and count over the row window, on the centre
  // pixel's surface.
  const auto slot = [&](int k) { return ring.data() + 4 * ws * size_t(k % rows_kept); };
  float* __restrict ax = acc.data();
  float* __restrict ay = ax + ws;
  float* __restrict az = ay + ws;
  float* __restrict ac = az + ws;
  float* __restrict sx = smoothed->x.data();
  float* __restrict sy = smoothed->y.data();
  float* __restrict sz = smoothed->z.data();
  for (int v = 0; v < h + r; ++v) {
    if (v < h) {
      float* rx = slot(v);
      float* ry = rx + ws;
      float* rz = ry + ws;
      float* rc = rz + ws;
      std::fill(rx, rx + 4 * ws, 0.0f);
      const size_t row = size_t(v) * ws;
      for (int k = -r; k <= r; ++k) {
        const int begin = std::max(0, -k), end = std::min(w, w - k);
        if (end <= begin) continue;
        const size_t c = row + size_t(begin), o = size_t(ptrdiff_t(c) + k);
        accumulateSameSurface(pz + c, pz + o, px + o, py + o, pz + o, nullptr, end - begin,
                              max_relative_distance, rx + begin, ry + begin, rz + begin,
                              rc + begin);
      }
    }
    const int out = v - r;  // the output row whose window is complete
    if (out < 0) continue;
    const size_t row = size_t(out) * ws;
    std::fill(acc.begin(), acc.end(), 0.0f);
    for (int k = std::max(-r, -out); k <= std::min(r, h - 1 - out); ++k) {
      const float* other = slot(out + k);
      accumulateSameSurface(pz + row, pz + size_t(out + k) * ws, other, other + ws,
                            other + 2 * ws, other + 3 * ws, w, max_relative_distance, ax, ay,
                            az, ac);
    }
    normaliseSums(pz + row, ax, ay, az, ac, w, sx + row, sy + row, sz + row);
  }
}

// The points as planes, straight from the depth (as depthToPoints computes them; 0 where
// unmeasured).
OBJDB_VECTOR_CLONES
void depthToPlanes(const DepthImage& depth, const Intrinsics& k, Planar3f* planes) {
  const int w = depth.width, h = depth.height;
  planes->resize(size_t(w) * size_t(h));
  const float fx_inv = float(1.0 / k.fx), fy_inv = float(1.0 / k.fy);
  const float cx = float(k.cx), cy = float(k.cy);
  thread_local std::vector<float> ru;
  ru.resize(size_t(w));
  for (int u = 0; u < w; ++u) ru[size_t(u)] = (float(u) - cx) * fx_inv;
  for (int v = 0; v < h; ++v) {
    const size_t row = size_t(v) * size_t(w);
    const float ry = (float(v) - cy) * fy_inv;
    const float* __restrict d = depth.data.data() + row;
    const float* __restrict rx = ru.data();
    float* __restrict x = planes->x.data() + row;
    float* __restrict y = planes->y.data() + row;
    float* __restrict z = planes->z.data() + row;
    for (int u = 0; u < w; ++u) {
      const float zu = measuredOrZero(d[u]);
      x[u] = rx[u] * zu;
      y[u] = ry * zu;
      z[u] = zu;
    }
  }
}

// A neighbour at depth zj is on the pixel's surface (depth z) when measured and within `limit`.
inline bool sameSurface(float zj, float z, float limit) {
  return (zj > 0.0f) & (std::abs(zj - z) <= limit);
}

struct Xyz {
  float x, y, z;
};

// The normal at a pixel from its smoothed point c and its four smoothed neighbours `offset`
// pixels away (r, l, d, u) with flags saying whether each is on the same surface: central
// differences where both sides are, one-sided otherwise; zero when a direction has neither or
// the pixel is unmeasured. Turned toward the camera. Selects only, values by value: the
// interior loop vectorises.
inline Xyz normalFromNeighbours(bool measured, bool right, bool left, bool down, bool up, Xyz c,
                                Xyz r, Xyz l, Xyz d, Xyz u) {
  const Xyz a = {(right ? r.x : c.x) - (left ? l.x : c.x), (right ? r.y : c.y) - (left ? l.y : c.y),
                 (right ? r.z : c.z) - (left ? l.z : c.z)};
  const Xyz b = {(down ? d.x : c.x) - (up ? u.x : c.x), (down ? d.y : c.y) - (up ? u.y : c.y),
                 (down ? d.z : c.z) - (up ? u.z : c.z)};
  const Xyz n = {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
  const float len2 = n.x * n.x + n.y * n.y + n.z * n.z;
  const bool ok = measured & (right | left) & (down | up) & (len2 > 1e-24f);
  float inv = 1.0f / std::sqrt(ok ? len2 : 1.0f);
  inv = ok ? inv : 0.0f;
  inv = n.x * c.x + n.y * c.y + n.z * c.z > 0.0f ? -inv : inv;
  return {n.x * inv, n.y * inv, n.z * inv};
}

// The normal of a pixel near the image border: neighbours outside the image count as not on
// the surface.
void normalAtBorder(const float* z_img, const Planar3f& S, int w, int h, int u, int v,
                    int offset, float max_relative_distance, Planar3f* normals) {
  const size_t i = size_t(v) * size_t(w) + size_t(u);
  const float z = z_img[i];
  const float limit = max_relative_distance * z;
  Xyz samples[4];
  bool flags[4];
  const int nu[4] = {u + offset, u - offset, u, u}, nv[4] = {v, v, v + offset, v - offset};
  for (int k = 0; k < 4; ++k) {
    const bool inside = nu[k] >= 0 && nu[k] < w && nv[k] >= 0 && nv[k] < h;
    const size_t j = inside ? size_t(nv[k]) * size_t(w) + size_t(nu[k]) : i;
    flags[k] = inside && sameSurface(z_img[j], z, limit);
    samples[k] = {S.x[j], S.y[j], S.z[j]};
  }
  const Xyz n = normalFromNeighbours(z > 0.0f, flags[0], flags[1], flags[2], flags[3],
                                     {S.x[i], S.y[i], S.z[i]}, samples[0], samples[1],
                                     samples[2], samples[3]);
  normals->x[i] = n.x;
  normals->y[i] = n.y;
  normals->z[i] = n.z;
}

// Interior normals of one row (every neighbour `offset` pixels away exists).
OBJDB_INLINE_KERNEL void normalsRow(const float* __restrict z_img, const float* __restrict sx,
                const float* __restrict sy, const float* __restrict sz, size_t first, int count,
                size_t o, size_t ow, float max_relative_distance, float* __restrict nx,
                float* __restrict ny, float* __restrict nz) {
  for (int t = 0; t < count; ++t) {
    const size_t i = first + size_t(t);
    const float z = z_img[i];
    const float limit = max_relative_distance * z;
    // Every load unconditional, then selects: the loop if-converts and vectorises.
    const Xyz n = normalFromNeighbours(
        z > 0.0f, sameSurface(z_img[i + o], z, limit), sameSurface(z_img[i - o], z, limit),
        sameSurface(z_img[i + ow], z, limit), sameSurface(z_img[i - ow], z, limit),
        {sx[i], sy[i], sz[i]}, {sx[i + o], sy[i + o], sz[i + o]},
        {sx[i - o], sy[i - o], sz[i - o]}, {sx[i + ow], sy[i + ow], sz[i + ow]},
        {sx[i - ow], sy[i - ow], sz[i - ow]});
    nx[i] = n.x;
    ny[i] = n.y;
    nz[i] = n.z;
  }
}

// Normals of every pixel from the smoothed points (see computeNormals).
OBJDB_VECTOR_CLONES
void normalsFromSmoothed(const float* z_img, const Planar3f& S, int w, int h, int offset,
                         float max_relative_distance, Planar3f* normals) {
  normals->resize(size_t(w) * size_t(h));
  for (int v = 0; v < h; ++v) {
    const bool border_row = v < offset || v + offset >= h || 2 * offset >= w;
    const int interior_begin = border_row ? w : offset;
    const int interior_end = border_row ? w : w - offset;
    for (int u = 0; u < interior_begin; ++u) {
      normalAtBorder(z_img, S, w, h, u, v, offset, max_relative_distance, normals);
    }
    normalsRow(z_img, S.x.data(), S.y.data(), S.z.data(),
               size_t(v) * size_t(w) + size_t(interior_begin), interior_end - interior_begin,
               size_t(offset), size_t(offset) * size_t(w), max_relative_distance,
               normals->x.data(), normals->y.data(), normals->z.data());
    for (int u = interior_end; u < w; ++u) {
      normalAtBorder(z_img, S, w, h, u, v, offset, max_relative_distance, normals);
    }
  }
}

// One row of pair values for convexityPlanes: i-side and j-side planes, `count` pairs.
OBJDB_INLINE_KERNEL void convexityPairs(const float* __restrict pxi, const float* __restrict pyi,
                    const float* __restrict pzi, const float* __restrict nxi,
                    const float* __restrict nyi, const float* __restrict nzi,
                    const float* __restrict pxj, const float* __restrict pyj,
                    const float* __restrict pzj, const float* __restrict nxj,
                    const float* __restrict nyj, const float* __restrict nzj, int count,
                    float offset_m, float offset_per_m2, float max_relative_jump,
                    float* __restrict pair) {
  for (int t = 0; t < count; ++t) {
    const float e0 = pxj[t] - pxi[t], e1 = pyj[t] - pyi[t], e2 = pzj[t] - pzi[t];
    // A zero normal (unknown) has n_z == 0: normals toward the camera have n_z < 0 except at
    // exactly grazing angles, which are boundaries anyway. Pairs across a depth jump belong to
    // the discontinuity map, not to convexity. Normals converge along a concave bend and
    // diverge along a convex one: (n_j − n_i)·(p_j − p_i) < −offset is concave (symmetric in
    // i and j, so a normal leaning across a nearby convex edge does not fake a concavity).
    const float bend = (nxj[t] - nxi[t]) * e0 + (nyj[t] - nyi[t]) * e1 + (nzj[t] - nzi[t]) * e2;
    // Chained selects: each compiles to a vector blend (with -fno-trapping-math).
    float value = nxi[t] * nxj[t] + nyi[t] * nyj[t] + nzi[t] * nzj[t];
    value = bend < -(offset_m + offset_per_m2 * pzi[t] * pzi[t]) ? value : 1.0f;
    value = std::abs(e2) <= max_relative_jump * pzi[t] ? value : 1.0f;
    value = nzi[t] != 0.0f ? value : 1.0f;
    value = nzj[t] != 0.0f ? value : 1.0f;
    pair[t] = value;
  }
}

// Min-convexity over planes (see convexityMap). Each pair (i, j) is visited once, from its first
// pixel, and its value lowers both pixels' minimum: 4 forward directions cover the
// 8-neighbourhood at distance k. Per row, the pair values go to `pair` first and are then
// min-ed into both ends: every loop is branch-free and vectorises.
OBJDB_VECTOR_CLONES
void convexityPlanes(const Planar3f& P, const Planar3f& N, int w, int h, int window,
                     float offset_m, float offset_per_m2, float max_relative_jump,
                     float* __restrict C) {
  const int k = std::max(1, window / 2);
  std::fill(C, C + size_t(w) * size_t(h), 1.0f);
  thread_local std::vector<float> pair_storage;
  pair_storage.resize(size_t(w));
  float* __restrict pair = pair_storage.data();
  const int du[4] = {k, 0, k, -k};
  const int dv[4] = {0, k, k, k};
  const float* __restrict px = P.x.data();
  const float* __restrict py = P.y.data();
  const float* __restrict pz = P.z.data();
  const float* __restrict nx = N.x.data();
  const float* __restrict ny = N.y.data();
  const float* __restrict nz = N.z.data();
  for (int d = 0; d < 4; ++d) {
    const ptrdiff_t step = ptrdiff_t(dv[d]) * w + du[d];
    const int u_begin = std::max(0, -du[d]), u_end = std::min(w, w - du[d]);
    if (u_end <= u_begin) continue;
    for (int v = 0; v + dv[d] < h; ++v) {
      const size_t first = size_t(v) * size_t(w) + size_t(u_begin);
      const int count = u_end - u_begin;
      const size_t second = size_t(ptrdiff_t(first) + step);
      convexityPairs(px + first, py + first, pz + first, nx + first, ny + first, nz + first,
                     px + second, py + second, pz + second, nx + second, ny + second,
                     nz + second, count, offset_m, offset_per_m2, max_relative_jump, pair);
      float* __restrict ci = C + first;
      for (int t = 0; t < count; ++t) ci[t] = std::min(ci[t], pair[t]);
      float* __restrict cj = C + second;
      for (int t = 0; t < count; ++t) cj[t] = std::min(cj[t], pair[t]);
    }
  }
}

void toPlanes(const Image<Eigen::Vector3f>& image, Planar3f* planes) {
  const size_t n = image.data.size();
  planes->resize(n);
  for (size_t i = 0; i < n; ++i) {
    planes->x[i] = image.data[i].x();
    planes->y[i] = image.data[i].y();
    planes->z[i] = image.data[i].z();
  }
}

void fromPlanes(const Planar3f& planes, int w, int h, Image<Eigen::Vector3f>* image) {
  resize(image, w, h, Eigen::Vector3f::Zero().eval());
  for (size_t i = 0; i < image->data.size(); ++i) {
    image->data[i] = Eigen::Vector3f(planes.x[i], planes.y[i], planes.z[i]);
  }
}

// Boundary pixels (unmeasured, a depth edge, concave or without a normal) and their complement.
OBJDB_VECTOR_CLONES
void boundaryMasks(const float* __restrict d, const uint8_t* __restrict e,
                   const float* __restrict c, const Planar3f& normals, float threshold, size_t n,
                   uint8_t* __restrict b, uint8_t* __restrict f) {
  const float* __restrict nx = normals.x.data();
  const float* __restrict ny = normals.y.data();
  const float* __restrict nz = normals.z.data();
  for (size_t i = 0; i < n; ++i) {
    // Bitwise, not short-circuit: the loop vectorises.
    const bool normal = (nx[i] != 0.0f) | (ny[i] != 0.0f) | (nz[i] != 0.0f);
    const bool free = (d[i] > 0.0f) & (e[i] == 0) & !(c[i] < threshold) & normal;
    b[i] = free ? 0 : 1;
    f[i] = free ? 1 : 0;
  }
}

// Each segment's pixels, points, normals (and mean colour) from the final label image.
void fillSegments(const LabelImage& labels, const PointImage& points, const Planar3f& normals,
                  const ColorImage* color, SegmentationResult* result) {
  const size_t n_pixels = labels.data.size();
  const size_t n = result->segments.size();
  std::vector<size_t> counts(n + 1, 0);
  for (size_t i = 0; i < n_pixels; ++i) ++counts[size_t(labels.data[i])];
  for (size_t l = 1; l <= n; ++l) {
    Segment& s = result->segments[l - 1];
    s.pixels.reserve(counts[l]);
    s.points.reserve(counts[l]);
    s.normals.reserve(counts[l]);
  }
  std::vector<Eigen::Vector3d> color_sums(color ? n : 0, Eigen::Vector3d::Zero());
  for (size_t i = 0; i < n_pixels; ++i) {
    const int32_t l = labels.data[i];
    if (l == 0) continue;
    Segment& s = result->segments[size_t(l - 1)];
    s.pixels.push_back(uint32_t(i));
    s.points.push_back(points.data[i]);
    s.normals.emplace_back(normals.x[i], normals.y[i], normals.z[i]);
    if (color) {
      const Rgb8 c = color->data[i];
      color_sums[size_t(l - 1)] += Eigen::Vector3d(c.r, c.g, c.b);
    }
  }
  if (color) {
    for (auto& s : result->segments) {
      const Eigen::Vector3d m =
          color_sums[size_t(s.label - 1)] / double(std::max<size_t>(1, s.pixels.size()));
      s.mean_color = Rgb8{uint8_t(std::lround(m.x())), uint8_t(std::lround(m.y())),
                          uint8_t(std::lround(m.z()))};
    }
  }
}

}  // namespace

void computeNormals(const PointImage& points, int window, float max_relative_distance,
                    NormalImage* normals) {
  const int w = points.width, h = points.height;
  Planar3f planes, smoothed, planar_normals;
  toPlanes(points, &planes);
  for (float& z : planes.z) z = std::max(0.0f, z);
  smoothPlanes(planes.x.data(), planes.y.data(), planes.z.data(), w, h, smoothingWindow(window),
               max_relative_distance, &smoothed);
  normalsFromSmoothed(planes.z.data(), smoothed, w, h, differenceOffset(window),
                      max_relative_distance, &planar_normals);
  fromPlanes(planar_normals, w, h, normals);
}

void convexityMap(const PointImage& points, const NormalImage& normals, int window,
                  float offset_m, float offset_per_m2, float max_relative_jump,
                  Image<float>* convexity) {
  const int w = points.width, h = points.height;
  resize(convexity, w, h, 1.0f);
  Planar3f p, n;
  toPlanes(points, &p);
  toPlanes(normals, &n);
  convexityPlanes(p, n, w, h, window, offset_m, offset_per_m2, max_relative_jump,
                  convexity->data.data());
}

DepthSegmenter::DepthSegmenter(const SegmentationParams& params, const Intrinsics& intrinsics)
    : params_(params), intrinsics_(intrinsics) {
  const double area_ratio =
      double(intrinsics.width) * intrinsics.height / (double(kVgaWidth) * 480.0);
  min_segment_px_ = std::max(1, int(std::lround(params.min_segment_px * area_ratio)));
  // Normals need a minimum support whatever the resolution: depth noise is per pixel.
  params_.normal_window_px = std::max(std::min(params.normal_window_px, kMinNormalWindow),
                                      scaledWindow(params.normal_window_px, intrinsics.width));
  params_.convexity_window_px = scaledWindow(params.convexity_window_px, intrinsics.width);
  params_.discontinuity_window_px = std::max(3, params.discontinuity_window_px);
}

StatusOr<DepthSegmenter> DepthSegmenter::create(const SegmentationParams& params,
                                                const Intrinsics& intrinsics) {
  OBJDB_RETURN_IF_ERROR(params.validate());
  OBJDB_RETURN_IF_ERROR(intrinsics.validate());
  return DepthSegmenter(params, intrinsics);
}

StatusOr<SegmentationResult> DepthSegmenter::segment(const DepthImage& depth,
                                                     const ColorImage* color,
                                                     SegmentationMaps* maps,
                                                     const SegmentOutputs& outputs) {
  const auto start = Clock::now();
  OBJDB_RETURN_IF_ERROR(intrinsics_.checkImageSize(depth.width, depth.height, "depth image"));
  if (depth.data.size() != size_t(depth.width) * size_t(depth.height)) {
    return absl::InvalidArgumentError("depth image has the wrong number of pixels");
  }
  if (color) {
    OBJDB_RETURN_IF_ERROR(intrinsics_.checkImageSize(color->width, color->height, "colour image"));
  }
  const int w = depth.width, h = depth.height;
  const size_t n_pixels = size_t(w) * size_t(h);
  SegmentationResult result;
  result.labels = LabelImage(w, h, 0);

  auto t = Clock::now();
  resize(&depth_, w, h, 0.0f);
  sanitiseDepth(depth.data.data(), n_pixels, depth_.data.data());
  if (params_.fill_holes_iterations > 0) {
    fillHoles(depth_.data.data(), nullptr, w, h, params_.fill_holes_iterations,
              params_.discontinuity_threshold, &scratch_);
  }
  for (float d : depth_.data) result.invalid_pixels += d > 0.0f ? 0 : 1;
  result.timings.filter_ms = msSince(t);
  t = Clock::now();
  depthToPlanes(depth_, intrinsics_, &planes_);
  // The points as an image only for the segments' points (the server's frame path skips them).
  if (outputs.segment_points) depthToPoints(depth_, intrinsics_, &points_);
  result.timings.points_ms = msSince(t);

  if (result.invalid_pixels == n_pixels) {
    result.timings.total_ms = msSince(start);
    return result;
  }

  t = Clock::now();
  discontinuityMap(depth_, params_.discontinuity_window_px, params_.discontinuity_threshold,
                   &edges_);
  result.timings.discontinuity_ms = msSince(t);

  t = Clock::now();
  smoothPlanes(planes_.x.data(), planes_.y.data(), planes_.z.data(), w, h,
               smoothingWindow(params_.normal_window_px), params_.normal_max_relative_distance,
               &smoothed_);
  normalsFromSmoothed(depth_.data.data(), smoothed_, w, h,
                      differenceOffset(params_.normal_window_px),
                      params_.normal_max_relative_distance, &normals_);
  result.timings.normals_ms = msSince(t);

  t = Clock::now();
  // Smoothed points: the tangent-plane test must not flip with per-pixel noise.
  resize(&convexity_, w, h, 1.0f);
  convexityPlanes(smoothed_, normals_, w, h, params_.convexity_window_px,
                  params_.convexity_offset_m, params_.convexity_offset_per_m2,
                  params_.normal_max_relative_distance, convexity_.data.data());
  result.timings.convexity_ms = msSince(t);

  t = Clock::now();
  resize(&boundaries_, w, h, uint8_t{0});
  cv::Mat free_space(h, w, CV_8U);
  boundaryMasks(depth_.data.data(), edges_.data.data(), convexity_.data.data(), normals_,
                params_.convexity_threshold, n_pixels, boundaries_.data.data(), free_space.data);
  // Components into a reused buffer; areas from one histogram pass (OpenCV's stats would also
  // compute bounding boxes and centroids we do not use).
  thread_local cv::Mat components;
  const int n_components =
      cv::connectedComponents(free_space, components, 4, CV_32S, cv::CCL_DEFAULT);
  const int32_t* comp = components.ptr<int32_t>();
  // Four partial histograms: neighbouring pixels mostly share a component, and one histogram
  // would wait on its own last increment (store-to-load forwarding) at every pixel.
  std::vector<uint32_t> partial(4 * size_t(n_components), 0);
  {
    uint32_t* __restrict a0 = partial.data();
    uint32_t* __restrict a1 = a0 + n_components;
    uint32_t* __restrict a2 = a1 + n_components;
    uint32_t* __restrict a3 = a2 + n_components;
    size_t i = 0;
    for (; i + 4 <= n_pixels; i += 4) {
      ++a0[comp[i]];
      ++a1[comp[i + 1]];
      ++a2[comp[i + 2]];
      ++a3[comp[i + 3]];
    }
    for (; i < n_pixels; ++i) ++a0[comp[i]];
  }
  std::vector<uint32_t> area(size_t(n_components), 0);
  for (size_t c = 0; c < size_t(n_components); ++c) {
    for (size_t k = 0; k < 4; ++k) area[c] += partial[k * size_t(n_components) + c];
  }
  std::vector<int32_t> final_label(size_t(n_components), 0);
  int32_t next = 0;
  for (int c = 1; c < n_components; ++c) {
    if (area[size_t(c)] >= uint32_t(min_segment_px_)) {
      final_label[size_t(c)] = ++next;
    } else {
      ++result.dropped_small;
    }
  }
  for (size_t i = 0; i < n_pixels; ++i) result.labels.data[i] = final_label[size_t(comp[i])];

  // Grow labels into boundary pixels whose 3D point is close to a labelled neighbour's, one ring
  // per pass; each pass looks only at the frontier the previous pass created.
  growLabels(depth_, normals_, intrinsics_, params_.label_growth_iterations,
             params_.max_label_growth_distance_m, &result.labels);
  result.timings.labels_ms = msSince(t);

  t = Clock::now();
  result.segments.resize(size_t(next));
  for (int32_t l = 1; l <= next; ++l) result.segments[size_t(l - 1)].label = l;
  for (size_t i = 0; i < n_pixels; ++i) {
    result.boundary_pixels += result.labels.data[i] == 0 && depth_.data[i] > 0.0f ? 1 : 0;
  }
  if (outputs.segment_points) fillSegments(result.labels, points_, normals_, color, &result);
  result.timings.segments_ms = msSince(t);

  if (maps) {
    maps->depth = depth_;
    maps->discontinuities = edges_;
    fromPlanes(normals_, w, h, &maps->normals);
    maps->convexity = convexity_;
    maps->boundaries = boundaries_;
  }
  result.timings.total_ms = msSince(start);
  return result;
}

}  // namespace objdb::segmentation
