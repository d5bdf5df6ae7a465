#include "core/segmentation/depth_segmenter.h"

#include <algorithm>
#include <chrono>
#include <cmath>

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

// Scales a window given for VGA to `width`, keeping it odd and ≥ 3.
int scaledWindow(int vga_window, int width) {
  const int w = static_cast<int>(std::lround(double(vga_window) * width / kVgaWidth));
  return std::max(3, w | 1);
}

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
  const int w = depth.width, h = depth.height, r = window / 2;
  resize(edges, w, h, uint8_t{0});
  for (int v = 0; v < h; ++v) {
    const int v0 = std::max(0, v - r), v1 = std::min(h - 1, v + r);
    for (int u = 0; u < w; ++u) {
      const float z = depth.data[size_t(v) * w + u];
      uint8_t edge = 0;
      if (isValidDepth(z)) {
        const float limit = threshold * z;
        const int u0 = std::max(0, u - r), u1 = std::min(w - 1, u + r);
        for (int vv = v0; vv <= v1 && !edge; ++vv) {
          const float* row = &depth.data[size_t(vv) * w];
          for (int uu = u0; uu <= u1; ++uu) {
            const float zn = row[uu];
            // Holes are not edges: only jumps to measured depth count.
            if (isValidDepth(zn) && std::abs(zn - z) > limit) {
              edge = 1;
              break;
            }
          }
        }
      }
      edges->data[size_t(v) * w + u] = edge;
    }
  }
}

namespace {

// Box-filtered points over valid pixels: smoothed(u, v) = mean of the valid points in the
// window (zero where none).
void smoothPoints(const PointImage& points, int window, PointImage* smoothed) {
  const int w = points.width, h = points.height;
  resize(smoothed, w, h, Eigen::Vector3f::Zero().eval());
  cv::Mat p(h, w, CV_32FC3, const_cast<Eigen::Vector3f*>(points.data.data()));
  cv::Mat valid(h, w, CV_32F);
  for (int i = 0; i < w * h; ++i) valid.at<float>(i) = points.data[size_t(i)].z() > 0 ? 1.f : 0.f;
  cv::Mat sum, count;
  cv::boxFilter(p, sum, CV_32F, cv::Size(window, window), cv::Point(-1, -1), false,
                cv::BORDER_CONSTANT);
  cv::boxFilter(valid, count, CV_32F, cv::Size(window, window), cv::Point(-1, -1), false,
                cv::BORDER_CONSTANT);
  const auto* s = reinterpret_cast<const Eigen::Vector3f*>(sum.ptr<float>());
  const float* c = count.ptr<float>();
  for (int i = 0; i < w * h; ++i) {
    smoothed->data[size_t(i)] =
        (c[i] > 0.5f && points.data[size_t(i)].z() > 0) ? Eigen::Vector3f(s[i] / c[i])
                                                         : Eigen::Vector3f::Zero();
  }
}

// Normals from the smoothed points (see computeNormals).
void normalsFromSmoothed(const PointImage& points, const PointImage& smoothed, int offset,
                         float max_relative_distance, NormalImage* normals) {
  const int w = points.width, h = points.height;
  resize(normals, w, h, Eigen::Vector3f::Zero().eval());
  auto consistent = [&](size_t a, size_t b) {
    const float za = points.data[a].z(), zb = points.data[b].z();
    return zb > 0 && std::abs(za - zb) <= max_relative_distance * za;
  };
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const size_t i = size_t(v) * w + u;
      Eigen::Vector3f& n = normals->data[i];
      n.setZero();
      if (!(points.data[i].z() > 0)) continue;
      // Horizontal difference, central where both sides are on the same surface.
      const bool right = u + offset < w && consistent(i, i + offset);
      const bool left = u - offset >= 0 && consistent(i, i - offset);
      const bool down = v + offset < h && consistent(i, i + size_t(offset) * w);
      const bool up = v - offset >= 0 && consistent(i, i - size_t(offset) * w);
      if (!(right || left) || !(down || up)) continue;
      const Eigen::Vector3f& c = smoothed.data[i];
      const Eigen::Vector3f dx = (right ? smoothed.data[i + offset] : c) -
                                 (left ? smoothed.data[i - offset] : c);
      const Eigen::Vector3f dy = (down ? smoothed.data[i + size_t(offset) * w] : c) -
                                 (up ? smoothed.data[i - size_t(offset) * w] : c);
      Eigen::Vector3f cross = dx.cross(dy);
      const float len = cross.norm();
      if (!(len > 1e-12f)) continue;
      cross /= len;
      if (cross.dot(c) > 0.0f) cross = -cross;  // toward the camera
      n = cross;
    }
  }
}

}  // namespace

void computeNormals(const PointImage& points, int window, float max_relative_distance,
                    NormalImage* normals) {
  PointImage smoothed;
  smoothPoints(points, window, &smoothed);
  normalsFromSmoothed(points, smoothed, std::max(1, window / 4), max_relative_distance, normals);
}

void convexityMap(const PointImage& points, const NormalImage& normals, int window,
                  float offset_m, Image<float>* convexity) {
  const int w = points.width, h = points.height, k = std::max(1, window / 2);
  resize(convexity, w, h, 1.0f);
  const int du[8] = {k, -k, 0, 0, k, -k, k, -k};
  const int dv[8] = {0, 0, k, -k, k, -k, -k, k};
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const size_t i = size_t(v) * w + u;
      const Eigen::Vector3f& n = normals.data[i];
      float min_convexity = 1.0f;
      if (n.z() != 0.0f || n.x() != 0.0f || n.y() != 0.0f) {
        const Eigen::Vector3f& p = points.data[i];
        for (int d = 0; d < 8; ++d) {
          const int uu = u + du[d], vv = v + dv[d];
          if (uu < 0 || vv < 0 || uu >= w || vv >= h) continue;
          const size_t j = size_t(vv) * w + uu;
          const Eigen::Vector3f& nj = normals.data[j];
          if (nj.isZero()) continue;
          // Neighbour in front of the tangent plane (toward the camera): a concave bend.
          if ((points.data[j] - p).dot(n) > offset_m) {
            min_convexity = std::min(min_convexity, n.dot(nj));
          }
        }
      }
      convexity->data[i] = min_convexity;
    }
  }
}

DepthSegmenter::DepthSegmenter(const SegmentationParams& params, const Intrinsics& intrinsics)
    : params_(params), intrinsics_(intrinsics) {
  const double area_ratio =
      double(intrinsics.width) * intrinsics.height / (double(kVgaWidth) * 480.0);
  min_segment_px_ = std::max(1, int(std::lround(params.min_segment_px * area_ratio)));
  params_.normal_window_px = scaledWindow(params.normal_window_px, intrinsics.width);
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
  smoothPoints(points_, params_.normal_window_px, &smoothed);
  normalsFromSmoothed(points_, smoothed, std::max(1, params_.normal_window_px / 4),
                      params_.normal_max_relative_distance, &normals_);
  result.timings.normals_ms = msSince(t);

  t = Clock::now();
  // Smoothed points: the tangent-plane test must not flip with per-pixel noise.
  convexityMap(smoothed, normals_, params_.convexity_window_px, params_.convexity_offset_m,
               &convexity_);
  result.timings.convexity_ms = msSince(t);

  t = Clock::now();
  resize(&boundaries_, w, h, uint8_t{0});
  cv::Mat free_space(h, w, CV_8U);
  for (size_t i = 0; i < n_pixels; ++i) {
    const bool boundary = !(depth_.data[i] > 0.0f) || edges_.data[i] != 0 ||
                          convexity_.data[i] < params_.convexity_threshold;
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

  // Grow labels into thin boundary pixels whose depth is close to a labelled neighbour's.
  std::vector<uint32_t> frontier, changed;
  for (int it = 0; it < params_.label_growth_iterations; ++it) {
    changed.clear();
    for (int v = 0; v < h; ++v) {
      for (int u = 0; u < w; ++u) {
        const size_t i = size_t(v) * w + u;
        const float z = depth_.data[i];
        if (result.labels.data[i] != 0 || !(z > 0.0f)) continue;
        int32_t best = 0;
        float best_gap = params_.max_label_growth_distance_m;
        const int nu[4] = {u - 1, u + 1, u, u}, nv[4] = {v, v, v - 1, v + 1};
        for (int d = 0; d < 4; ++d) {
          if (nu[d] < 0 || nv[d] < 0 || nu[d] >= w || nv[d] >= h) continue;
          const size_t j = size_t(nv[d]) * w + nu[d];
          const int32_t l = result.labels.data[j];
          if (l == 0) continue;
          const float gap = (points_.data[j] - points_.data[i]).norm();
          if (gap <= best_gap) {
            best_gap = gap;
            best = l;
          }
        }
        if (best != 0) {
          changed.push_back(uint32_t(i));
          changed.push_back(uint32_t(best));
        }
      }
    }
    if (changed.empty()) break;
    for (size_t c = 0; c < changed.size(); c += 2) result.labels.data[changed[c]] = int32_t(changed[c + 1]);
  }
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
