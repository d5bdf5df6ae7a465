#include "core/segmentation/depth_segmenter.h"

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

// The normal window W is split into a box filter of about W/3 (noise) and central differences
// W/3 pixels apart (baseline): the footprint stays W wide while a silhouette contaminates only
// the W/6 pixels next to it.
int smoothingWindow(int normal_window) { return std::max(1, (normal_window / 3) | 1); }
int differenceOffset(int normal_window) { return std::max(1, normal_window / 3); }

template <typename T>
void resize(Image<T>* image, int w, int h, T fill) {
  if (image->width != w || image->height != h) *image = Image<T>(w, h, fill);
}

}  // namespace

size_t fillDepthHoles(DepthImage* depth, int iterations) {
  const int w = depth->width, h = depth->height;
  size_t filled = 0;
  DepthImage next = *depth;
  for (int it = 0; it < iterations; ++it) {
    size_t filled_now = 0;
    for (int v = 1; v + 1 < h; ++v) {
      for (int u = 1; u + 1 < w; ++u) {
        if (isValidDepth(depth->at(u, v))) continue;
        float sum = 0.0f;
        int n = 0;
        for (int dv = -1; dv <= 1; ++dv) {
          for (int du = -1; du <= 1; ++du) {
            const float d = depth->at(u + du, v + dv);
            if (isValidDepth(d)) {
              sum += d;
              ++n;
            }
          }
        }
        // Only holes surrounded on most sides: never grow the image outward at its borders.
        if (n >= 5) {
          next.at(u, v) = sum / float(n);
          ++filled_now;
        }
      }
    }
    if (filled_now == 0) break;
    filled += filled_now;
    *depth = next;
  }
  return filled;
}

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

void discontinuityMap(const DepthImage& depth, int window, float threshold, MaskImage* edges) {
  const int w = depth.width, h = depth.height;
  resize(edges, w, h, uint8_t{0});
  // Largest jump to a measured neighbour = max(dilate(d) − d, d − erode(d)), with holes
  // excluded from both (0 never wins a max, +inf never wins a min): holes are not edges.
  thread_local cv::Mat clean, for_min, dilated, eroded;
  clean.create(h, w, CV_32F);
  for_min.create(h, w, CV_32F);
  float* c = clean.ptr<float>();
  float* m = for_min.ptr<float>();
  const float kInf = std::numeric_limits<float>::infinity();
  for (size_t i = 0; i < depth.data.size(); ++i) {
    const bool valid = isValidDepth(depth.data[i]);
    c[i] = valid ? depth.data[i] : 0.0f;
    m[i] = valid ? depth.data[i] : kInf;
  }
  const cv::Mat kernel = cv::getStructuringElement(cv::MORPH_RECT, cv::Size(window, window));
  cv::dilate(clean, dilated, kernel, cv::Point(-1, -1), 1, cv::BORDER_CONSTANT, cv::Scalar(0));
  cv::erode(for_min, eroded, kernel, cv::Point(-1, -1), 1, cv::BORDER_CONSTANT, cv::Scalar(kInf));
  const float* hi = dilated.ptr<float>();
  const float* lo = eroded.ptr<float>();
  for (size_t i = 0; i < depth.data.size(); ++i) {
    const float z = c[i];
    const float jump = std::max(hi[i] - z, z - lo[i]);
    edges->data[i] = uint8_t(z > 0.0f && jump > threshold * z);
  }
}

namespace {

// Box-filtered points over valid pixels: smoothed(u, v) = mean of the valid points in the
// window (zero where none).
void smoothPoints(const PointImage& points, int window, PointImage* smoothed) {
  const int w = points.width, h = points.height;
  resize(smoothed, w, h, Eigen::Vector3f::Zero().eval());
  const size_t n = size_t(w) * size_t(h);
  // Four channels (x, y, z, valid) filtered in one pass.
  thread_local cv::Mat packed, sum;
  packed.create(h, w, CV_32FC4);
  const float* p = points.data.data()->data();
  float* q = packed.ptr<float>();
  for (size_t i = 0; i < n; ++i) {
    q[4 * i] = p[3 * i];
    q[4 * i + 1] = p[3 * i + 1];
    q[4 * i + 2] = p[3 * i + 2];
    q[4 * i + 3] = p[3 * i + 2] > 0.0f ? 1.0f : 0.0f;
  }
  cv::boxFilter(packed, sum, CV_32F, cv::Size(window, window), cv::Point(-1, -1), false,
                cv::BORDER_CONSTANT);
  const float* s = sum.ptr<float>();
  float* out = smoothed->data.data()->data();
  for (size_t i = 0; i < n; ++i) {
    const float c = s[4 * i + 3];
    const bool ok = c > 0.5f && p[3 * i + 2] > 0.0f;
    const float inv = ok ? 1.0f / c : 0.0f;
    out[3 * i] = s[4 * i] * inv;
    out[3 * i + 1] = s[4 * i + 1] * inv;
    out[3 * i + 2] = s[4 * i + 2] * inv;
  }
}

// Normals from the smoothed points (see computeNormals).
void normalsFromSmoothed(const PointImage& points, const PointImage& smoothed, int offset,
                         float max_relative_distance, NormalImage* normals) {
  const int w = points.width, h = points.height;
  resize(normals, w, h, Eigen::Vector3f::Zero().eval());
  const float* P = points.data.data()->data();
  const float* S = smoothed.data.data()->data();
  float* N = normals->data.data()->data();
  const size_t row = size_t(w);
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const size_t i = size_t(v) * row + size_t(u);
      float* n = N + 3 * i;
      n[0] = n[1] = n[2] = 0.0f;
      const float z = P[3 * i + 2];
      if (!(z > 0.0f)) continue;
      const float limit = max_relative_distance * z;
      auto consistent = [&](size_t j) {
        const float zj = P[3 * j + 2];
        return zj > 0.0f && std::abs(zj - z) <= limit;
      };
      // Central differences where both sides are on the same surface, one-sided otherwise.
      const bool right = u + offset < w && consistent(i + size_t(offset));
      const bool left = u >= offset && consistent(i - size_t(offset));
      const bool down = v + offset < h && consistent(i + size_t(offset) * row);
      const bool up = v >= offset && consistent(i - size_t(offset) * row);
      if (!(right || left) || !(down || up)) continue;
      const float* c = S + 3 * i;
      const float* r = right ? S + 3 * (i + size_t(offset)) : c;
      const float* l = left ? S + 3 * (i - size_t(offset)) : c;
      const float* d = down ? S + 3 * (i + size_t(offset) * row) : c;
      const float* t = up ? S + 3 * (i - size_t(offset) * row) : c;
      const float dx0 = r[0] - l[0], dx1 = r[1] - l[1], dx2 = r[2] - l[2];
      const float dy0 = d[0] - t[0], dy1 = d[1] - t[1], dy2 = d[2] - t[2];
      float n0 = dx1 * dy2 - dx2 * dy1;
      float n1 = dx2 * dy0 - dx0 * dy2;
      float n2 = dx0 * dy1 - dx1 * dy0;
      const float len2 = n0 * n0 + n1 * n1 + n2 * n2;
      if (!(len2 > 1e-24f)) continue;
      float inv = 1.0f / std::sqrt(len2);
      if (n0 * c[0] + n1 * c[1] + n2 * c[2] > 0.0f) inv = -inv;  // toward the camera
      n[0] = n0 * inv;
      n[1] = n1 * inv;
      n[2] = n2 * inv;
    }
  }
}

// Grows labels into unlabelled measured pixels (see DepthSegmenter::segment).
void growLabels(const DepthImage& depth, const PointImage& points, const NormalImage& normals,
                int iterations, float max_distance, LabelImage* labels) {
  const int w = depth.width, h = depth.height;
  int32_t* L = labels->data.data();
  // Only pixels with a normal join a segment: segments promise unit normals.
  auto unlabelled = [&](size_t i) {
    const Eigen::Vector3f& n = normals.data[i];
    return L[i] == 0 && depth.data[i] > 0.0f && (n.x() != 0.0f || n.y() != 0.0f || n.z() != 0.0f);
  };
  std::vector<uint32_t> frontier, next;
  std::vector<std::pair<uint32_t, int32_t>> changes;
  std::vector<uint8_t> queued(size_t(w) * size_t(h), 0);
  auto push_neighbours = [&](size_t i, std::vector<uint32_t>* out) {
    const int u = int(i % size_t(w)), v = int(i / size_t(w));
    const int nu[4] = {u - 1, u + 1, u, u}, nv[4] = {v, v, v - 1, v + 1};
    for (int d = 0; d < 4; ++d) {
      if (nu[d] < 0 || nv[d] < 0 || nu[d] >= w || nv[d] >= h) continue;
      const size_t j = size_t(nv[d]) * size_t(w) + size_t(nu[d]);
      if (unlabelled(j) && !queued[j]) {
        queued[j] = 1;
        out->push_back(uint32_t(j));
      }
    }
  };
  // The first frontier: growable pixels with a labelled 4-neighbour.
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const size_t i = size_t(v) * size_t(w) + size_t(u);
      if (!unlabelled(i)) continue;
      const bool touches = (u > 0 && L[i - 1] != 0) || (u + 1 < w && L[i + 1] != 0) ||
                           (v > 0 && L[i - size_t(w)] != 0) || (v + 1 < h && L[i + size_t(w)] != 0);
      if (touches) {
        queued[i] = 1;
        frontier.push_back(uint32_t(i));
      }
    }
  }
  for (int it = 0; it < iterations && !frontier.empty(); ++it) {
    changes.clear();
    for (uint32_t i : frontier) {
      queued[i] = 0;
      const int u = int(i % uint32_t(w)), v = int(i / uint32_t(w));
      const int nu[4] = {u - 1, u + 1, u, u}, nv[4] = {v, v, v - 1, v + 1};
      int32_t best = 0;
      float best_gap = max_distance;
      for (int d = 0; d < 4; ++d) {
        if (nu[d] < 0 || nv[d] < 0 || nu[d] >= w || nv[d] >= h) continue;
        const size_t j = size_t(nv[d]) * size_t(w) + size_t(nu[d]);
        if (L[j] == 0) continue;
        const float gap = (points.data[j] - points.data[i]).norm();
        if (gap <= best_gap) {
          best_gap = gap;
          best = L[j];
        }
      }
      if (best != 0) changes.emplace_back(i, best);
    }
    for (const auto& [i, label] : changes) L[i] = label;
    next.clear();
    for (const auto& [i, label] : changes) push_neighbours(i, &next);
    frontier.swap(next);
  }
}

}  // namespace

void computeNormals(const PointImage& points, int window, float max_relative_distance,
                    NormalImage* normals) {
  PointImage smoothed;
  smoothPoints(points, smoothingWindow(window), &smoothed);
  normalsFromSmoothed(points, smoothed, differenceOffset(window), max_relative_distance, normals);
}

void convexityMap(const PointImage& points, const NormalImage& normals, int window,
                  float offset_m, float max_relative_jump, Image<float>* convexity) {
  const int w = points.width, h = points.height, k = std::max(1, window / 2);
  resize(convexity, w, h, 1.0f);
  std::fill(convexity->data.begin(), convexity->data.end(), 1.0f);
  // Each pair (i, j) is visited once, from its first pixel, and its value lowers both pixels'
  // minimum: 4 forward directions cover the 8-neighbourhood at distance k.
  const int du[4] = {k, 0, k, -k};
  const int dv[4] = {0, k, k, k};
  const float* P = points.data.data()->data();
  const float* N = normals.data.data()->data();
  float* C = convexity->data.data();
  // Direction outermost and exact row ranges: the inner loop has no bounds checks.
  for (int d = 0; d < 4; ++d) {
    const ptrdiff_t step = ptrdiff_t(dv[d]) * w + du[d];
    const int u_begin = std::max(0, -du[d]), u_end = std::min(w, w - du[d]);
    for (int v = 0; v + dv[d] < h; ++v) {
      for (int u = u_begin; u < u_end; ++u) {
        const size_t i = size_t(v) * size_t(w) + size_t(u);
        const size_t j = size_t(ptrdiff_t(i) + step);
        const float* n = N + 3 * i;
        const float* nj = N + 3 * j;
        // A zero normal (unknown) has n[2] == 0: normals toward the camera have n[2] < 0
        // except at exactly grazing angles, which are boundaries anyway.
        if (n[2] == 0.0f || nj[2] == 0.0f) continue;
        const float* p = P + 3 * i;
        const float* pj = P + 3 * j;
        // Pairs across a depth jump belong to the discontinuity map, not to convexity.
        if (std::abs(pj[2] - p[2]) > max_relative_jump * p[2]) continue;
        const float e0 = pj[0] - p[0], e1 = pj[1] - p[1], e2 = pj[2] - p[2];
        // Normals converge along a concave bend and diverge along a convex one:
        // (n_j − n_i)·(p_j − p_i) < 0 is concave. Symmetric in i and j, so a normal that leans
        // across a nearby convex edge does not fake a concavity.
        if ((nj[0] - n[0]) * e0 + (nj[1] - n[1]) * e1 + (nj[2] - n[2]) * e2 >= -offset_m) continue;
        const float dot = n[0] * nj[0] + n[1] * nj[1] + n[2] * nj[2];
        C[i] = std::min(C[i], dot);
        C[j] = std::min(C[j], dot);
      }
    }
  }
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
                                                     SegmentationMaps* maps) {
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
  depth_ = depth;
  for (float& d : depth_.data) {
    if (!isValidDepth(d)) d = 0.0f;  // NaN, inf, negative → no measurement
  }
  if (params_.fill_holes_iterations > 0) fillDepthHoles(&depth_, params_.fill_holes_iterations);
  for (float d : depth_.data) result.invalid_pixels += d > 0.0f ? 0 : 1;
  depthToPoints(depth_, intrinsics_, &points_);
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
  PointImage& smoothed = smoothed_;
  smoothPoints(points_, smoothingWindow(params_.normal_window_px), &smoothed);
  normalsFromSmoothed(points_, smoothed, differenceOffset(params_.normal_window_px),
                      params_.normal_max_relative_distance, &normals_);
  result.timings.normals_ms = msSince(t);

  t = Clock::now();
  // Smoothed points: the tangent-plane test must not flip with per-pixel noise.
  convexityMap(smoothed, normals_, params_.convexity_window_px, params_.convexity_offset_m,
               params_.normal_max_relative_distance, &convexity_);
  result.timings.convexity_ms = msSince(t);

  t = Clock::now();
  resize(&boundaries_, w, h, uint8_t{0});
  cv::Mat free_space(h, w, CV_8U);
  for (size_t i = 0; i < n_pixels; ++i) {
    const Eigen::Vector3f& n = normals_.data[i];
    const bool boundary = !(depth_.data[i] > 0.0f) || edges_.data[i] != 0 ||
                          convexity_.data[i] < params_.convexity_threshold ||
                          (n.x() == 0.0f && n.y() == 0.0f && n.z() == 0.0f);
    boundaries_.data[i] = boundary ? 1 : 0;
    free_space.data[i] = boundary ? 0 : 1;
  }
  cv::Mat components, stats, centroids;
  const int n_components =
      cv::connectedComponentsWithStats(free_space, components, stats, centroids, 4, CV_32S);
  std::vector<int32_t> final_label(size_t(n_components), 0);
  int32_t next = 0;
  for (int c = 1; c < n_components; ++c) {
    if (stats.at<int>(c, cv::CC_STAT_AREA) >= min_segment_px_) {
      final_label[size_t(c)] = ++next;
    } else {
      ++result.dropped_small;
    }
  }
  const int32_t* comp = components.ptr<int32_t>();
  for (size_t i = 0; i < n_pixels; ++i) result.labels.data[i] = final_label[size_t(comp[i])];

  // Grow labels into boundary pixels whose 3D point is close to a labelled neighbour's, one ring
  // per pass; each pass looks only at the frontier the previous pass created.
  growLabels(depth_, points_, normals_, params_.label_growth_iterations,
             params_.max_label_growth_distance_m, &result.labels);
  result.timings.labels_ms = msSince(t);

  t = Clock::now();
  result.segments.resize(size_t(next));
  std::vector<size_t> counts(size_t(next) + 1, 0);
  for (size_t i = 0; i < n_pixels; ++i) ++counts[size_t(result.labels.data[i])];
  for (int32_t l = 1; l <= next; ++l) {
    Segment& s = result.segments[size_t(l - 1)];
    s.label = l;
    s.pixels.reserve(counts[size_t(l)]);
    s.points.reserve(counts[size_t(l)]);
    s.normals.reserve(counts[size_t(l)]);
  }
  std::vector<Eigen::Vector3d> color_sums(color ? size_t(next) : 0, Eigen::Vector3d::Zero());
  for (size_t i = 0; i < n_pixels; ++i) {
    const int32_t l = result.labels.data[i];
    if (l == 0) {
      if (depth_.data[i] > 0.0f) ++result.boundary_pixels;
      continue;
    }
    Segment& s = result.segments[size_t(l - 1)];
    s.pixels.push_back(uint32_t(i));
    s.points.push_back(points_.data[i]);
    s.normals.push_back(normals_.data[i]);
    if (color) {
      const Rgb8 c = color->data[i];
      color_sums[size_t(l - 1)] += Eigen::Vector3d(c.r, c.g, c.b);
    }
  }
  if (color) {
    for (auto& s : result.segments) {
      const Eigen::Vector3d m = color_sums[size_t(s.label - 1)] / double(std::max<size_t>(1, s.pixels.size()));
      s.mean_color = Rgb8{uint8_t(std::lround(m.x())), uint8_t(std::lround(m.y())),
                          uint8_t(std::lround(m.z()))};
    }
  }
  result.timings.segments_ms = msSince(t);

  if (maps) {
    maps->depth = depth_;
    maps->discontinuities = edges_;
    maps->normals = normals_;
    maps->convexity = convexity_;
    maps->boundaries = boundaries_;
  }
  result.timings.total_ms = msSince(start);
  return result;
}

}  // namespace objdb::segmentation
