// Geometric segmentation of single depth frames (paper §III-A, after Uckermann et al. and
// Tateno et al.): depth-discontinuity edges + concave boundaries from a normal-based convexity
// map cut the image into closed regions; each region above a minimum size becomes a labelled 3D
// segment. Labels are per frame only — the GSM (§III-B) makes them consistent over time.
//
// Every step is a separate function on plain images so it can be tested and shown on its own;
// DepthSegmenter runs them in order with no per-pixel allocation and reports per-step timings.
#pragma once

#include <cstdint>
#include <optional>
#include <vector>

#include <Eigen/Core>

#include "core/common/image.h"
#include "core/common/intrinsics.h"
#include "core/common/params.h"

namespace objdb::segmentation {

// Camera-frame 3D point per pixel; z = 0 marks "no measurement".
using PointImage = Image<Eigen::Vector3f>;
// Unit normals pointing toward the camera; zero vector = unknown.
using NormalImage = Image<Eigen::Vector3f>;
using MaskImage = Image<uint8_t>;      // 0 / 1
using LabelImage = Image<int32_t>;     // 0 = no segment

// Fills holes (0 depth) with the mean of the valid pixels of their 3×3 neighbourhood, when at
// least 5 of the 8 are valid and they lie on one surface (max − min ≤ max_relative_spread · min,
// the discontinuity test's own ratio), in up to `iterations` passes. Closes the pinholes of
// depth registered to a larger colour image (a RealSense's grid of holes); holes on depth edges
// stay. Returns the number of pixels filled.
size_t fillDepthHoles(DepthImage* depth, int iterations, float max_relative_spread = 0.03f);

// Back-projects a depth image; invalid (0, NaN, ±inf, negative) depth → point (0, 0, 0).
void depthToPoints(const DepthImage& depth, const Intrinsics& intrinsics, PointImage* points);

// Depth discontinuities: 1 where the largest depth difference to a valid pixel in the
// window × window neighbourhood exceeds `threshold` · depth (relative jump).
void discontinuityMap(const DepthImage& depth, int window, float threshold, MaskImage* edges);

// Normals from the pixel neighbourhood: the point image is box-filtered over about window/3
// pixels, averaging only the neighbours on the pixel's own surface (|Δz| ≤
// `max_relative_distance` · z, so a silhouette does not bend the normals next to it), and the
// normal is the cross product of central differences of the smoothed points window/3 pixels
// apart, falling back to one-sided differences across a depth jump of more than
// `max_relative_distance` · z. A plane gives its exact normal; noise is averaged over the window.
void computeNormals(const PointImage& points, int window, float max_relative_distance,
                    NormalImage* normals);

// Min-convexity map in [−1, 1]: for each pixel, the minimum over its neighbours `window` / 2
// pixels away in 8 directions of 1 where the pair is convex or flat, else (concave:
// (n_j − n_i)·(p_j − p_i) < −(offset_m + offset_per_m2 · z_i²), the normals converge) the dot
// product of the two normals. Pairs whose depths differ by more than `max_relative_jump` · z are
// skipped (depth jumps are the discontinuity map's business).
void convexityMap(const PointImage& points, const NormalImage& normals, int window,
                  float offset_m, float offset_per_m2, float max_relative_jump,
                  Image<float>* convexity);

// Three float planes (x, y, z) of a w × h image: the segmenter's internal layout, which the
// compiler can vectorise.
struct Planar3f {
  std::vector<float> x, y, z;
  void resize(size_t n) {
    x.resize(n);
    y.resize(n);
    z.resize(n);
  }
};

// Segments of one frame.
struct Segment {
  int32_t label = 0;                       // 1.. in this frame
  std::vector<uint32_t> pixels;            // row-major pixel indices
  std::vector<Eigen::Vector3f> points;     // camera frame, metres
  std::vector<Eigen::Vector3f> normals;    // unit, toward the camera
  std::optional<Rgb8> mean_color;          // when a colour image was given
};

struct SegmentationTimings {
  double filter_ms = 0, points_ms = 0, discontinuity_ms = 0, normals_ms = 0, convexity_ms = 0, labels_ms = 0,
         segments_ms = 0, total_ms = 0;
};

struct SegmentationResult {
  LabelImage labels;          // 0 = no segment
  std::vector<Segment> segments;
  size_t invalid_pixels = 0;  // no measurement (incl. NaN / inf / negative)
  size_t boundary_pixels = 0; // valid but on an edge after label growth
  size_t dropped_small = 0;   // regions below the minimum size
  SegmentationTimings timings;
};

// Intermediate maps of the last run (for pictures and tests).
struct SegmentationMaps {
  DepthImage depth;           // after optional hole filling
  MaskImage discontinuities;
  NormalImage normals;
  Image<float> convexity;
  MaskImage boundaries;       // discontinuity ∪ concave ∪ invalid
};

// What segment() fills in beyond the label image.
struct SegmentOutputs {
  // Each segment's pixels, points, normals and mean colour. Without them the segments hold only
  // their labels (the GSM fuses the label image alone: the server's frame path skips them).
  bool segment_points = true;
};

class DepthSegmenter {
 public:
  // Params are validated; the minimum segment size is given for VGA (640×480) and scaled with
  // the image area for other resolutions.
  static StatusOr<DepthSegmenter> create(const SegmentationParams& params,
                                         const Intrinsics& intrinsics);

  // Segments one frame. Errors: image size differs from the intrinsics, colour size differs.
  // All-invalid depth gives an empty result, not an error.
  StatusOr<SegmentationResult> segment(const DepthImage& depth,
                                       const ColorImage* color = nullptr,
                                       SegmentationMaps* maps = nullptr,
                                       const SegmentOutputs& outputs = {});

  const SegmentationParams& params() const { return params_; }
  int minSegmentPixels() const { return min_segment_px_; }

 private:
  DepthSegmenter(const SegmentationParams& params, const Intrinsics& intrinsics);
  SegmentationParams params_;
  Intrinsics intrinsics_;
  int min_segment_px_ = 0;
  // Scratch buffers reused between frames.
  DepthImage depth_;
  PointImage points_;
  Planar3f planes_;  // the points, as planes
  Planar3f smoothed_;
  Planar3f normals_;
  MaskImage edges_;
  MaskImage boundaries_;
  Image<float> convexity_;
  std::vector<float> scratch_;
};

}  // namespace objdb::segmentation
