// Known-answer tests of the single-frame depth segmentation (paper §III-A): scenes rendered by
// core/sim with exact ground-truth instance ids, analytic depth images for the per-step maps, and
// every bad input the segmentation issue names.
#include "core/segmentation/depth_segmenter.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Geometry>

#include "core/common/params.h"
#include "core/sim/noise.h"
#include "core/sim/renderer.h"
#include "core/sim/shapes.h"
#include "tests/support/reference_segmentation.h"

namespace objdb::segmentation {
namespace {

using sim::RenderInstance;
using sim::RenderOutput;

constexpr double kDegPerRad = 180.0 / M_PI;

bool contains(absl::string_view text, absl::string_view part) {
  return text.find(part) != absl::string_view::npos;
}

Transform poseAt(double x, double y, double z, double yaw_rad = 0.0) {
  return poseFromXyzYaw(Eigen::Vector3d(x, y, z), yaw_rad);
}

// Camera 1.5 m from `target`, `pitch_deg` below the horizon, looking along world +x.
Transform cameraLookingDown(const Eigen::Vector3d& target, double distance_m, double pitch_deg) {
  const double p = pitch_deg / kDegPerRad;
  const Eigen::Vector3d position =
      target + Eigen::Vector3d(-distance_m * std::cos(p), 0.0, distance_m * std::sin(p));
  return lookAt(position, target).value();
}

RenderOutput render(const Intrinsics& k, const std::vector<RenderInstance>& instances,
                    const Transform& T_world_camera, const sim::DepthNoiseParams* noise = nullptr) {
  const sim::Renderer renderer(k);
  RenderOutput out;
  renderer.render(instances, T_world_camera, &out);
  if (noise) sim::applyDepthNoise(*noise, 0, out.cos_incidence, &out.depth);
  return out;
}

DepthSegmenter makeSegmenter(const Intrinsics& k, const SegmentationParams& params = {}) {
  StatusOr<DepthSegmenter> segmenter = DepthSegmenter::create(params, k);
  EXPECT_TRUE(segmenter.ok()) << segmenter.status();
  return *std::move(segmenter);
}

// Overlap of segments (labels) with ground-truth instances.
struct Overlap {
  std::map<int32_t, std::map<uint16_t, size_t>> per_segment;  // label → instance → pixels
  std::map<int32_t, size_t> segment_size;
  std::map<uint16_t, size_t> instance_size;

  Overlap(const LabelImage& labels, const InstanceImage& instances) {
    for (size_t i = 0; i < labels.data.size(); ++i) {
      const uint16_t g = instances.data[i];
      if (g != 0) ++instance_size[g];
      const int32_t l = labels.data[i];
      if (l == 0) continue;
      ++segment_size[l];
      ++per_segment[l][g];
    }
  }
  // Share of the segment's pixels belonging to its majority instance.
  double purity(int32_t label) const {
    size_t best = 0;
    for (const auto& [g, n] : per_segment.at(label)) best = std::max(best, n);
    return double(best) / double(segment_size.at(label));
  }
  uint16_t majority(int32_t label) const {
    size_t best = 0;
    uint16_t id = 0;
    for (const auto& [g, n] : per_segment.at(label)) {
      if (n > best) best = n, id = g;
    }
    return id;
  }
  // Share of the instance's pixels inside its best segment.
  double coverage(uint16_t instance) const {
    size_t best = 0;
    for (const auto& [l, m] : per_segment) {
      const auto it = m.find(instance);
      if (it != m.end()) best = std::max(best, it->second);
    }
    const auto it = instance_size.find(instance);
    return it == instance_size.end() ? 0.0 : double(best) / double(it->second);
  }
  std::string describe() const {
    std::ostringstream s;
    for (const auto& [l, m] : per_segment) {
      s << "  segment " << l << ": " << segment_size.at(l) << " px,";
      for (const auto& [g, n] : m) s << " instance " << g << " " << n;
      s << "\n";
    }
    for (const auto& [g, n] : instance_size) s << "  instance " << g << ": " << n << " px\n";
    return s.str();
  }
};

// --- The synthetic world's two boxes on a floor --------------------------------------------------

constexpr uint16_t kBoxA = 1, kBoxB = 2, kFloor = 3;

struct TwoBoxes {
  TriangleMesh floor = sim::makePlane(6.0f, 6.0f);
  TriangleMesh box_a = sim::makeBox({0.5f, 0.4f, 0.45f});
  TriangleMesh box_b = sim::makeBox({0.4f, 0.45f, 0.4f});
  std::vector<RenderInstance> instances() const {
    return {RenderInstance{&floor, Transform::Identity(), kFloor, {120, 160, 90}},
            RenderInstance{&box_a, poseAt(0.0, -0.4, 0.225, 0.3), kBoxA, {200, 60, 40}},
            RenderInstance{&box_b, poseAt(0.1, 0.4, 0.2, -0.4), kBoxB, {40, 80, 220}}};
  }
  // VGA camera 1.5 m from the point between the boxes, 40° down.
  Transform camera() const { return cameraLookingDown({0.0, 0.0, 0.15}, 1.5, 40.0); }
};

TEST(DepthSegmenter, TwoBoxesOnAFloorGiveExactlyThreeSegments) {
  const TwoBoxes world;
  const Intrinsics k = Intrinsics::vga();
  const RenderOutput frame = render(k, world.instances(), world.camera());
  const Overlap truth(LabelImage(k.width, k.height, 0), frame.instances);
  ASSERT_GT(truth.instance_size.at(kBoxA), 10000u);
  ASSERT_GT(truth.instance_size.at(kBoxB), 10000u);
  ASSERT_GT(truth.instance_size.at(kFloor), 50000u);

  DepthSegmenter segmenter = makeSegmenter(k);
  StatusOr<SegmentationResult> result = segmenter.segment(frame.depth, &frame.color);
  ASSERT_TRUE(result.ok()) << result.status();
  const Overlap overlap(result->labels, frame.instances);
  EXPECT_EQ(result->segments.size(), 3u) << overlap.describe();
  EXPECT_GE(overlap.coverage(kBoxA), 0.90) << overlap.describe();
  EXPECT_GE(overlap.coverage(kBoxB), 0.90) << overlap.describe();
  EXPECT_GE(overlap.coverage(kFloor), 0.90) << overlap.describe();
  for (const Segment& s : result->segments) {
    EXPECT_GE(overlap.purity(s.label), 0.95) << "segment " << s.label << "\n" << overlap.describe();
  }
  EXPECT_EQ(result->invalid_pixels, 0u);  // the floor fills the whole image
  // The three segments are three different instances.
  std::set<uint16_t> majorities;
  for (const Segment& s : result->segments) majorities.insert(overlap.majority(s.label));
  EXPECT_EQ(majorities, (std::set<uint16_t>{kBoxA, kBoxB, kFloor})) << overlap.describe();
}

TEST(DepthSegmenter, TwoBoxesWithSensorNoiseGiveThreeLargeSegments) {
  const TwoBoxes world;
  const Intrinsics k = Intrinsics::vga();
  const sim::DepthNoiseParams noise;  // the default (Kinect-like) model
  const RenderOutput frame = render(k, world.instances(), world.camera(), &noise);

  DepthSegmenter segmenter = makeSegmenter(k);
  StatusOr<SegmentationResult> result = segmenter.segment(frame.depth, &frame.color);
  ASSERT_TRUE(result.ok()) << result.status();
  const Overlap overlap(result->labels, frame.instances);
  const size_t large = size_t(k.width) * size_t(k.height) / 100;  // 1 % of the image
  std::set<uint16_t> majorities;
  size_t n_large = 0;
  for (const Segment& s : result->segments) {
    if (s.pixels.size() < large) continue;
    ++n_large;
    majorities.insert(overlap.majority(s.label));
    EXPECT_GE(overlap.purity(s.label), 0.95) << "segment " << s.label << "\n" << overlap.describe();
  }
  EXPECT_EQ(n_large, 3u) << overlap.describe();
  EXPECT_EQ(majorities, (std::set<uint16_t>{kBoxA, kBoxB, kFloor})) << overlap.describe();
  // Each box still mostly in one segment despite the noise.
  EXPECT_GE(overlap.coverage(kBoxA), 0.80) << overlap.describe();
  EXPECT_GE(overlap.coverage(kBoxB), 0.80) << overlap.describe();
}

// The server asks for the label image only: the same labels, segments and counts, without the
// per-segment point lists.
TEST(DepthSegmenter, LabelsOnlyGivesTheSameLabelsWithoutPointLists) {
  const TwoBoxes world;
  const Intrinsics k = Intrinsics::vga();
  const sim::DepthNoiseParams noise;
  const RenderOutput frame = render(k, world.instances(), world.camera(), &noise);
  DepthSegmenter segmenter = makeSegmenter(k);
  StatusOr<SegmentationResult> full = segmenter.segment(frame.depth, &frame.color);
  StatusOr<SegmentationResult> labels_only =
      segmenter.segment(frame.depth, &frame.color, nullptr, {/*segment_points=*/false});
  ASSERT_TRUE(full.ok()) << full.status();
  ASSERT_TRUE(labels_only.ok()) << labels_only.status();
  EXPECT_EQ(labels_only->labels.data, full->labels.data);
  ASSERT_EQ(labels_only->segments.size(), full->segments.size());
  ASSERT_GE(full->segments.size(), 3u);
  for (size_t i = 0; i < full->segments.size(); ++i) {
    EXPECT_EQ(labels_only->segments[i].label, full->segments[i].label);
    EXPECT_FALSE(full->segments[i].pixels.empty());
    EXPECT_TRUE(labels_only->segments[i].pixels.empty());
    EXPECT_TRUE(labels_only->segments[i].points.empty());
    EXPECT_FALSE(labels_only->segments[i].mean_color.has_value());
  }
  EXPECT_EQ(labels_only->boundary_pixels, full->boundary_pixels);
  EXPECT_GT(full->boundary_pixels, 0u);
  EXPECT_EQ(labels_only->invalid_pixels, full->invalid_pixels);
}

// --- Concave edges split, convex edges do not ----------------------------------------------------

TEST(DepthSegmenter, ConcaveFloorWallCornerSplitsIntoTwoSegments) {
  const TriangleMesh floor = sim::makePlane(8.0f, 8.0f);
  // Wall 4 m high in the plane x = 1, facing −x (toward the camera).
  const TriangleMesh wall = sim::makePlane(4.0f, 8.0f);
  const Transform T_world_wall =
      sim::translationRotation(1.0f, 0.0f, 2.0f, Eigen::Vector3d::UnitY(), -M_PI / 2);
  const Intrinsics k = Intrinsics::vga();
  const Transform camera = lookAt({-0.5, 0.0, 1.0}, {1.0, 0.0, 0.3}).value();
  const RenderOutput frame = render(
      k, {RenderInstance{&floor, Transform::Identity(), 1}, RenderInstance{&wall, T_world_wall, 2}},
      camera);
  const Overlap truth(LabelImage(k.width, k.height, 0), frame.instances);
  ASSERT_GT(truth.instance_size.at(1), 30000u);
  ASSERT_GT(truth.instance_size.at(2), 30000u);

  DepthSegmenter segmenter = makeSegmenter(k);
  StatusOr<SegmentationResult> result = segmenter.segment(frame.depth);
  ASSERT_TRUE(result.ok()) << result.status();
  const Overlap overlap(result->labels, frame.instances);
  ASSERT_EQ(result->segments.size(), 2u) << overlap.describe();
  for (const Segment& s : result->segments) {
    EXPECT_GE(overlap.purity(s.label), 0.98) << overlap.describe();
  }
  EXPECT_GE(overlap.coverage(1), 0.95) << overlap.describe();
  EXPECT_GE(overlap.coverage(2), 0.95) << overlap.describe();
}

// Two half-planes meeting at a vertical edge 1.5 m in front of an identity camera, each bent
// 40° away from the image plane; `toward_camera` = a convex ridge, else a concave valley.
struct Hinge {
  TriangleMesh half = sim::makePlane(6.0f, 6.0f);
  std::vector<RenderInstance> instances(bool toward_camera) const {
    const double a = 40.0 / kDegPerRad;
    const double z_edge = toward_camera ? 1.5 : 2.5;
    std::vector<RenderInstance> out;
    for (int side : {-1, 1}) {
      // Local +x of the plane runs from the edge outward: (side·cos a, 0, ±sin a).
      const Eigen::Vector3d dir(side * std::cos(a), 0.0,
                                (toward_camera ? 1.0 : -1.0) * std::sin(a));
      Transform T = Transform::Identity();
      T.linear().col(0) = dir;
      T.linear().col(1) = Eigen::Vector3d::UnitY();
      T.linear().col(2) = dir.cross(Eigen::Vector3d::UnitY());
      T.translation() = Eigen::Vector3d(0.0, 0.0, z_edge) + 3.0 * dir;
      out.push_back(RenderInstance{&half, T, uint16_t(side < 0 ? 1 : 2)});
    }
    return out;
  }
};

TEST(DepthSegmenter, ConcaveValleySplitsAtItsEdge) {
  const Hinge hinge;
  const Intrinsics k = Intrinsics::vga();
  const RenderOutput frame = render(k, hinge.instances(false), Transform::Identity());
  ASSERT_EQ(std::count(frame.depth.data.begin(), frame.depth.data.end(), 0.0f), 0);
  DepthSegmenter segmenter = makeSegmenter(k);
  StatusOr<SegmentationResult> result = segmenter.segment(frame.depth);
  ASSERT_TRUE(result.ok()) << result.status();
  const Overlap overlap(result->labels, frame.instances);
  ASSERT_EQ(result->segments.size(), 2u) << overlap.describe();
  for (const Segment& s : result->segments) {
    EXPECT_GE(overlap.purity(s.label), 0.98) << overlap.describe();
  }
  EXPECT_GE(overlap.coverage(1), 0.95) << overlap.describe();
  EXPECT_GE(overlap.coverage(2), 0.95) << overlap.describe();
}

TEST(DepthSegmenter, ConvexRidgeStaysOneSegment) {
  const Hinge hinge;
  const Intrinsics k = Intrinsics::vga();
  const RenderOutput frame = render(k, hinge.instances(true), Transform::Identity());
  ASSERT_EQ(std::count(frame.depth.data.begin(), frame.depth.data.end(), 0.0f), 0);
  DepthSegmenter segmenter = makeSegmenter(k);
  StatusOr<SegmentationResult> result = segmenter.segment(frame.depth);
  ASSERT_TRUE(result.ok()) << result.status();
  const Overlap overlap(result->labels, frame.instances);
  ASSERT_EQ(result->segments.size(), 1u) << overlap.describe();
  EXPECT_GE(double(result->segments[0].pixels.size()), 0.98 * double(k.width * k.height));
}

// Share of the valid pixels with depth in [z_min, z_max) that the convexity map marks concave.
double concaveShare(const SegmentationMaps& maps, float threshold, float z_min, float z_max) {
  size_t valid = 0, concave = 0;
  for (size_t i = 0; i < maps.depth.data.size(); ++i) {
    const float z = maps.depth.data[i];
    if (!(z >= z_min && z < z_max)) continue;
    ++valid;
    if (maps.convexity.data[i] < threshold) ++concave;
  }
  EXPECT_GT(valid, 5000u) << z_min << ".." << z_max << " m";
  return valid == 0 ? 0.0 : double(concave) / double(valid);
}

// Sensor noise grows with depth² (σ 2.6 cm at 4 m for the Kinect-like model): far away, a fixed
// tangent-plane offset lets noise mark flat surfaces concave. The offset's z² term removes most
// of those marks beyond 4 m, leaves few either way near the camera, and a real concave valley
// with the same noise still splits.
TEST(DepthSegmenter, TheConvexityOffsetGrowsWithDepthSoNoiseFarAwayIsNotConcave) {
  const sim::DepthNoiseParams noise;
  const Intrinsics k = Intrinsics::vga();
  // A wall turned 60° about the vertical axis, 3 m in front of the camera at the image centre:
  // its depth runs from about 1 m to beyond 5 m across the image.
  const TriangleMesh wall = sim::makePlane(12.0f, 12.0f);
  Transform T_camera_wall = Transform::Identity();
  T_camera_wall.linear() =
      Eigen::AngleAxisd(60.0 / kDegPerRad, Eigen::Vector3d::UnitY()).toRotationMatrix();
  T_camera_wall.translation() = Eigen::Vector3d(0.0, 0.0, 3.0);
  const RenderOutput frame =
      render(k, {RenderInstance{&wall, T_camera_wall, 1}}, Transform::Identity(), &noise);

  SegmentationParams fixed_offset;
  fixed_offset.convexity_offset_per_m2 = 0.0f;
  const SegmentationParams defaults;
  ASSERT_GT(defaults.convexity_offset_per_m2, 0.0f);
  double near_share[2], far_share[2];
  for (int i = 0; i < 2; ++i) {
    DepthSegmenter segmenter = makeSegmenter(k, i == 0 ? fixed_offset : defaults);
    SegmentationMaps maps;
    StatusOr<SegmentationResult> result = segmenter.segment(frame.depth, nullptr, &maps);
    ASSERT_TRUE(result.ok()) << result.status();
    near_share[i] = concaveShare(maps, defaults.convexity_threshold, 0.5f, 3.0f);
    far_share[i] = concaveShare(maps, defaults.convexity_threshold, 4.0f, 100.0f);
  }
  EXPECT_GT(far_share[0], 0.01) << "noise should fake concave pixels far away with a fixed offset";
  EXPECT_LT(far_share[1], 0.5 * far_share[0]) << far_share[0] << " -> " << far_share[1];
  EXPECT_LT(near_share[0], 0.005);
  EXPECT_LT(near_share[1], 0.005);

  // The concave valley (edge 2.5 m away, planes reaching beyond 4 m) with the same noise.
  const Hinge hinge;
  const RenderOutput valley = render(k, hinge.instances(false), Transform::Identity(), &noise);
  DepthSegmenter segmenter = makeSegmenter(k, defaults);
  StatusOr<SegmentationResult> result = segmenter.segment(valley.depth);
  ASSERT_TRUE(result.ok()) << result.status();
  const Overlap overlap(result->labels, valley.instances);
  std::set<uint16_t> majorities;
  for (const Segment& s : result->segments) {
    if (s.pixels.size() < size_t(k.width * k.height) / 20) continue;
    EXPECT_GE(overlap.purity(s.label), 0.95) << overlap.describe();
    majorities.insert(overlap.majority(s.label));
  }
  EXPECT_EQ(majorities, (std::set<uint16_t>{1, 2})) << overlap.describe();
}

TEST(DepthSegmenter, BigBoxSeenOnItsEdgeIsOneSegmentCoveringBothFaces) {
  const TriangleMesh box = sim::makeBox({2.0f, 2.0f, 2.0f});
  const Intrinsics k = Intrinsics::vga();
  // Box turned 45° about the vertical: the camera at its mid-height sees two side faces meeting
  // at the vertical edge 1.09 m away, and nothing else (background invalid).
  const RenderOutput frame = render(k, {RenderInstance{&box, poseAt(2.5, 0.0, 0.0, M_PI / 4), 1}},
                                    lookAt({0.0, 0.0, 0.0}, {1.0, 0.0, 0.0}).value());
  const Overlap truth(LabelImage(k.width, k.height, 0), frame.instances);
  ASSERT_GT(truth.instance_size.at(1), 100000u);
  ASSERT_GT(std::count(frame.depth.data.begin(), frame.depth.data.end(), 0.0f), 10000);

  DepthSegmenter segmenter = makeSegmenter(k);
  StatusOr<SegmentationResult> result = segmenter.segment(frame.depth);
  ASSERT_TRUE(result.ok()) << result.status();
  const Overlap overlap(result->labels, frame.instances);
  ASSERT_EQ(result->segments.size(), 1u) << overlap.describe();
  EXPECT_GE(overlap.coverage(1), 0.95) << overlap.describe();
  // Both faces: pixels left and right of the edge (image centre column) are in the segment.
  size_t left = 0, right = 0;
  for (uint32_t i : result->segments[0].pixels) {
    if (int(i % uint32_t(k.width)) < k.width / 2) {
      ++left;
    } else {
      ++right;
    }
  }
  EXPECT_GT(left, truth.instance_size.at(1) / 3);
  EXPECT_GT(right, truth.instance_size.at(1) / 3);
}

// --- Normals -------------------------------------------------------------------------------------

// A plane through (0, 0, distance) in front of an identity camera, tilted 40° about the camera
// x axis, and its unit normal toward the camera.
struct TiltedPlane {
  TriangleMesh mesh = sim::makePlane(30.0f, 30.0f, 1.0f);
  Transform T;
  Eigen::Vector3f normal;
  explicit TiltedPlane(double distance_m) {
    T = Transform::Identity();
    T.linear() = Eigen::AngleAxisd(40.0 / kDegPerRad, Eigen::Vector3d::UnitX()).toRotationMatrix();
    T.translation() = Eigen::Vector3d(0, 0, distance_m);
    Eigen::Vector3d n = T.linear() * Eigen::Vector3d::UnitZ();
    if (n.dot(T.translation()) > 0) n = -n;
    normal = n.cast<float>();
  }
};

double angleDeg(const Eigen::Vector3f& a, const Eigen::Vector3f& b) {
  return std::acos(std::clamp(double(a.normalized().dot(b.normalized())), -1.0, 1.0)) * kDegPerRad;
}

TEST(ComputeNormals, TiltedPlaneNormalsWithinOneDegree) {
  const TiltedPlane plane(2.0);
  const Intrinsics k = Intrinsics::vga();
  const RenderOutput frame =
      render(k, {RenderInstance{&plane.mesh, plane.T, 1}}, Transform::Identity());
  PointImage points;
  depthToPoints(frame.depth, k, &points);
  const SegmentationParams params;
  const int window = params.normal_window_px;
  NormalImage normals;
  computeNormals(points, window, params.normal_max_relative_distance, &normals);
  ASSERT_EQ(normals.width, k.width);
  ASSERT_EQ(normals.height, k.height);
  double worst = 0.0;
  for (int v = window; v < k.height - window; ++v) {
    for (int u = window; u < k.width - window; ++u) {
      const Eigen::Vector3f& n = normals.at(u, v);
      ASSERT_NEAR(n.norm(), 1.0f, 1e-4f) << u << "," << v;
      worst = std::max(worst, angleDeg(n, plane.normal));
    }
  }
  EXPECT_LT(worst, 1.0);
}

TEST(ComputeNormals, NoisyTiltedPlaneHasSmallMeanAngleError) {
  const TiltedPlane plane(1.0);
  const Intrinsics k = Intrinsics::vga();
  const sim::DepthNoiseParams noise;
  const RenderOutput frame =
      render(k, {RenderInstance{&plane.mesh, plane.T, 1}}, Transform::Identity(), &noise);
  PointImage points;
  depthToPoints(frame.depth, k, &points);
  const SegmentationParams params;
  const int window = params.normal_window_px;
  NormalImage normals;
  computeNormals(points, window, params.normal_max_relative_distance, &normals);
  double sum = 0.0;
  size_t n = 0, missing = 0;
  for (int v = window; v < k.height - window; ++v) {
    for (int u = window; u < k.width - window; ++u) {
      if (!isValidDepth(frame.depth.at(u, v))) continue;
      const Eigen::Vector3f& normal = normals.at(u, v);
      if (normal.isZero()) {
        ++missing;
        continue;
      }
      ASSERT_NEAR(normal.norm(), 1.0f, 1e-4f);
      sum += angleDeg(normal, plane.normal);
      ++n;
    }
  }
  ASSERT_GT(n, 200000u);
  EXPECT_LT(double(missing), 0.01 * double(n));
  EXPECT_LT(sum / double(n), 2.0);
}

TEST(ComputeNormals, InvalidPixelsHaveNoNormal) {
  const Intrinsics k = Intrinsics::vga();
  DepthImage depth(k.width, k.height, 1.5f);
  for (int v = 100; v < 200; ++v) {
    for (int u = 100; u < 200; ++u) depth.at(u, v) = 0.0f;
  }
  depth.at(400, 300) = std::numeric_limits<float>::quiet_NaN();
  PointImage points;
  depthToPoints(depth, k, &points);
  EXPECT_TRUE(points.at(400, 300).isZero());
  EXPECT_TRUE(points.at(150, 150).isZero());
  NormalImage normals;
  computeNormals(points, 13, 0.05f, &normals);
  EXPECT_TRUE(normals.at(150, 150).isZero());
  EXPECT_TRUE(normals.at(400, 300).isZero());
  // A fronto-parallel plane: normal (0, 0, −1), also right next to the hole.
  EXPECT_LT(angleDeg(normals.at(320, 100), Eigen::Vector3f(0, 0, -1)), 0.1);
  EXPECT_LT(angleDeg(normals.at(99, 150), Eigen::Vector3f(0, 0, -1)), 0.1);
}

// Two fronto-parallel planes, 1.5 m and 2 m away, meet at a silhouette (straight across the
// image, down it, and on a diagonal staircase). Smoothing must not average the two surfaces:
// every pixel of both, right up to the jump, keeps the exact normal (0, 0, −1). A plain box
// filter bends the normals of the pixels next to the jump into a ramp.
TEST(ComputeNormals, ASilhouetteDoesNotBendTheNormalsOnEitherSide) {
  const Intrinsics k = Intrinsics::vga();
  const std::vector<std::pair<std::string, std::function<bool(int, int)>>> steps = {
      {"vertical", [](int u, int) { return u < 320; }},
      {"horizontal", [](int, int v) { return v < 240; }},
      {"diagonal", [](int u, int v) { return u + v < 560; }}};
  for (const auto& [name, near] : steps) {
    DepthImage depth(k.width, k.height, 2.0f);
    for (int v = 0; v < k.height; ++v) {
      for (int u = 0; u < k.width; ++u) depth.at(u, v) = near(u, v) ? 1.5f : 2.0f;
    }
    PointImage points;
    depthToPoints(depth, k, &points);
    NormalImage normals;
    computeNormals(points, 13, 0.05f, &normals);
    // Only a pixel with no same-surface neighbour in one direction has no normal: where the
    // staircase meets the image border (neighbours are 13 / 3 = 4 pixels apart).
    double worst = 0.0;
    size_t missing = 0;
    for (int v = 0; v < k.height; ++v) {
      for (int u = 0; u < k.width; ++u) {
        if (normals.at(u, v).isZero()) {
          ++missing;
          EXPECT_TRUE(v < 4 || v >= k.height - 4) << name << " " << u << "," << v;
          continue;
        }
        worst = std::max(worst, angleDeg(normals.at(u, v), Eigen::Vector3f(0, 0, -1)));
      }
    }
    EXPECT_LE(missing, 40u) << name;
    EXPECT_LT(worst, 0.01) << name;
  }
}

TEST(DepthToPoints, BackProjectsValidPixelsAndZeroesInvalidOnes) {
  const Intrinsics k{8, 6, 5.0, 6.0, 3.5, 2.5};
  DepthImage depth(8, 6, 2.0f);
  depth.at(1, 1) = std::numeric_limits<float>::quiet_NaN();
  depth.at(2, 1) = std::numeric_limits<float>::infinity();
  depth.at(3, 1) = -std::numeric_limits<float>::infinity();
  depth.at(4, 1) = -1.0f;
  depth.at(5, 1) = 0.0f;
  depth.at(6, 4) = 3.0f;
  PointImage points;
  depthToPoints(depth, k, &points);
  for (int u = 1; u <= 5; ++u) EXPECT_TRUE(points.at(u, 1).isZero()) << u;
  EXPECT_TRUE(points.at(6, 4).isApprox(k.backProject(6, 4, 3.0).cast<float>(), 1e-6f));
  EXPECT_TRUE(points.at(0, 0).isApprox(k.backProject(0, 0, 2.0).cast<float>(), 1e-6f));
}

// --- Discontinuities -----------------------------------------------------------------------------

TEST(DiscontinuityMap, MarksADepthStepButNotASmoothSlope) {
  const int w = 60, h = 40, window = 3;
  const float threshold = 0.03f;
  // Left half 1.0 m, right half 1.5 m: a 50 % jump at u = 30.
  DepthImage step(w, h, 1.0f);
  for (int v = 0; v < h; ++v) {
    for (int u = 30; u < w; ++u) step.at(u, v) = 1.5f;
  }
  MaskImage edges;
  discontinuityMap(step, window, threshold, &edges);
  ASSERT_EQ(edges.width, w);
  ASSERT_EQ(edges.height, h);
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const bool near_step = u >= 30 - window / 2 && u < 30 + window / 2;
      EXPECT_EQ(edges.at(u, v), near_step ? 1 : 0) << u << "," << v;
    }
  }
  // A slope of 0.5 % of the depth per pixel (a steep plane) is no discontinuity.
  DepthImage slope(w, h, 0.0f);
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) slope.at(u, v) = 1.0f + 0.005f * float(u + v);
  }
  discontinuityMap(slope, window, threshold, &edges);
  EXPECT_EQ(std::count(edges.data.begin(), edges.data.end(), uint8_t{1}), 0);
}

TEST(DiscontinuityMap, HolesAndNonFiniteDepthsAreNotEdges) {
  const int w = 50, h = 50;
  DepthImage depth(w, h, 2.0f);
  for (int v = 10; v < 20; ++v) {
    for (int u = 10; u < 20; ++u) depth.at(u, v) = 0.0f;
  }
  depth.at(30, 30) = std::numeric_limits<float>::quiet_NaN();
  depth.at(35, 30) = std::numeric_limits<float>::infinity();
  depth.at(40, 30) = -std::numeric_limits<float>::infinity();
  depth.at(30, 40) = -2.0f;
  MaskImage edges;
  discontinuityMap(depth, 5, 0.03f, &edges);
  EXPECT_EQ(std::count(edges.data.begin(), edges.data.end(), uint8_t{1}), 0);
}

// --- Hole filling --------------------------------------------------------------------------------

TEST(FillDepthHoles, FillsASmallHoleWithItsNeighboursDepthAndKeepsTheBorder) {
  DepthImage depth(20, 20, 1.25f);
  depth.at(10, 10) = 0.0f;
  depth.at(0, 5) = 0.0f;  // on the image border: never filled
  const size_t filled = fillDepthHoles(&depth, 3);
  EXPECT_EQ(filled, 1u);
  EXPECT_FLOAT_EQ(depth.at(10, 10), 1.25f);
  EXPECT_EQ(depth.at(0, 5), 0.0f);
}

TEST(FillDepthHoles, ClosesAGridOfPinholesButNotAHoleOnADepthEdge) {
  // Every other pixel of every other row missing (depth registered to a larger colour image).
  DepthImage grid(16, 16, 2.0f);
  for (int v = 1; v < 16; v += 2) {
    for (int u = 1; u < 16; u += 2) grid.at(u, v) = 0.0f;
  }
  EXPECT_EQ(fillDepthHoles(&grid, 1), 49u);  // the 7 x 7 inside the border
  EXPECT_FLOAT_EQ(grid.at(7, 7), 2.0f);
  // A hole between a surface at 1 m and one at 2 m: its neighbours disagree by far more than the
  // 3 % of a surface, so it stays (averaging would put a point in mid-air).
  DepthImage edge(10, 10, 1.0f);
  for (int v = 0; v < 10; ++v) {
    for (int u = 5; u < 10; ++u) edge.at(u, v) = 2.0f;
  }
  edge.at(5, 5) = 0.0f;
  EXPECT_EQ(fillDepthHoles(&edge, 3), 0u);
  EXPECT_EQ(edge.at(5, 5), 0.0f);
}

// The vectorised kernels against plain scalar loops, on a noisy image with holes, NaN and ±inf.
DepthImage randomDepthWithHoles(int w, int h, uint32_t seed) {
  DepthImage depth(w, h, 0.0f);
  uint32_t x = seed;
  const auto next = [&x] {
    x = x * 1664525u + 1013904223u;
    return float(x >> 8) / float(1u << 24);
  };
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const float r = next();
      float d = (u < w / 2 ? 1.0f : 1.6f) + 0.01f * next();  // two surfaces and a step
      if (r < 0.15f) d = 0.0f;
      else if (r < 0.16f) d = std::numeric_limits<float>::quiet_NaN();
      else if (r < 0.165f) d = std::numeric_limits<float>::infinity();
      else if (r < 0.17f) d = -1.0f;
      depth.at(u, v) = d;
    }
  }
  return depth;
}

TEST(FillDepthHoles, MatchesAScalarReferenceBitForBit) {
  for (const auto& [w, h] : {std::pair{37, 23}, std::pair{64, 48}, std::pair{3, 3}}) {
    DepthImage depth = randomDepthWithHoles(w, h, uint32_t(w * 7 + h));
    DepthImage reference = depth;
    size_t reference_filled = 0;
    for (int it = 0; it < 2; ++it) {
      DepthImage next = reference;
      for (int v = 1; v + 1 < h; ++v) {
        for (int u = 1; u + 1 < w; ++u) {
          if (isValidDepth(reference.at(u, v))) continue;
          float sum = 0.0f, lo = std::numeric_limits<float>::max(), hi = 0.0f;
          int n = 0;
          for (int dv = -1; dv <= 1; ++dv) {
            for (int du = -1; du <= 1; ++du) {
              const float d = reference.at(u + du, v + dv);
              if (!isValidDepth(d)) continue;
              sum += d, lo = std::min(lo, d), hi = std::max(hi, d), ++n;
            }
          }
          if (n >= 5 && hi - lo <= 0.03f * lo) {
            next.at(u, v) = sum / float(n);
            ++reference_filled;
          }
        }
      }
      reference = next;
    }
    EXPECT_EQ(fillDepthHoles(&depth, 2), reference_filled) << w << "x" << h;
    for (size_t i = 0; i < depth.data.size(); ++i) {
      const float a = depth.data[i], b = reference.data[i];
      EXPECT_TRUE(a == b || (std::isnan(a) && std::isnan(b))) << "pixel " << i << ": " << a
                                                             << " vs " << b;
    }
  }
}

TEST(DiscontinuityMap, MatchesAScalarReference) {
  for (const int window : {3, 5}) {
    const int w = 41, h = 29;
    const DepthImage depth = randomDepthWithHoles(w, h, uint32_t(window));
    MaskImage edges;
    discontinuityMap(depth, window, 0.03f, &edges);
    const int r = window / 2;
    for (int v = 0; v < h; ++v) {
      for (int u = 0; u < w; ++u) {
        const float z = depth.at(u, v);
        bool edge = false;
        if (isValidDepth(z)) {
          for (int dv = -r; dv <= r; ++dv) {
            for (int du = -r; du <= r; ++du) {
              const int uu = u + du, vv = v + dv;
              if (uu < 0 || vv < 0 || uu >= w || vv >= h) continue;
              const float d = depth.at(uu, vv);
              if (isValidDepth(d) && std::abs(d - z) > 0.03f * z) edge = true;
            }
          }
        }
        EXPECT_EQ(edges.at(u, v), edge ? 1 : 0) << "window " << window << " at " << u << ","
                                                << v;
      }
    }
  }
}

// --- Minimum segment size ------------------------------------------------------------------------

TEST(DepthSegmenter, RegionSmallerThanTheMinimumIsDroppedAndCounted) {
  const TriangleMesh tiny = sim::makeBox({0.04f, 0.04f, 0.04f});
  const TriangleMesh wall = sim::makePlane(10.0f, 10.0f);
  const Intrinsics k = Intrinsics::vga();
  // Identity camera; a tiny box 1.5 m away in front of a wall at 3 m.
  const Transform T_box =
      sim::translationRotation(0.0f, 0.0f, 1.5f, Eigen::Vector3d(1, 1, 0).normalized(), 0.5);
  const Transform T_wall = poseAt(0.0, 0.0, 3.0);
  DepthSegmenter segmenter = makeSegmenter(k);

  // The box alone, background invalid: nothing survives.
  RenderOutput frame = render(k, {RenderInstance{&tiny, T_box, 5}}, Transform::Identity());
  const Overlap alone(LabelImage(k.width, k.height, 0), frame.instances);
  ASSERT_GT(alone.instance_size.at(5), 50u);
  ASSERT_LT(int(alone.instance_size.at(5)), segmenter.minSegmentPixels());
  StatusOr<SegmentationResult> result = segmenter.segment(frame.depth);
  ASSERT_TRUE(result.ok()) << result.status();
  EXPECT_TRUE(result->segments.empty());
  EXPECT_GE(result->dropped_small, 1u);
  EXPECT_EQ(std::count(result->labels.data.begin(), result->labels.data.end(), 0),
            k.width * k.height);

  // In front of a wall: the wall is the only segment and no box pixel is labelled.
  frame = render(k, {RenderInstance{&tiny, T_box, 5}, RenderInstance{&wall, T_wall, 6}},
                 Transform::Identity());
  result = segmenter.segment(frame.depth);
  ASSERT_TRUE(result.ok()) << result.status();
  const Overlap overlap(result->labels, frame.instances);
  ASSERT_EQ(result->segments.size(), 1u) << overlap.describe();
  EXPECT_EQ(overlap.majority(1), 6);
  EXPECT_GE(result->dropped_small, 1u);
  EXPECT_EQ(overlap.per_segment.at(1).count(5), 0u) << overlap.describe();
}

TEST(DepthSegmenter, MinimumSizeScalesWithTheImageArea) {
  SegmentationParams params;
  params.min_segment_px = 400;
  EXPECT_EQ(makeSegmenter(Intrinsics::vga(), params).minSegmentPixels(), 400);
  const Intrinsics half{320, 240, 262.5, 262.5, 159.5, 119.5};
  EXPECT_EQ(makeSegmenter(half, params).minSegmentPixels(), 100);
  EXPECT_GE(makeSegmenter(Intrinsics{1, 1, 1.0, 1.0, 0.5, 0.5}, params).minSegmentPixels(), 1);
}

// --- Bad input -----------------------------------------------------------------------------------

TEST(DepthSegmenter, AllInvalidDepthGivesAnEmptyResult) {
  const Intrinsics k = Intrinsics::vga();
  DepthSegmenter segmenter = makeSegmenter(k);
  for (float fill : {0.0f, std::numeric_limits<float>::quiet_NaN(), -1.0f}) {
    const DepthImage depth(k.width, k.height, fill);
    SegmentationMaps maps;
    StatusOr<SegmentationResult> result = segmenter.segment(depth, nullptr, &maps);
    ASSERT_TRUE(result.ok()) << result.status();
    EXPECT_TRUE(result->segments.empty());
    EXPECT_EQ(result->invalid_pixels, size_t(k.width) * size_t(k.height));
    EXPECT_EQ(result->labels.width, k.width);
    EXPECT_EQ(result->labels.height, k.height);
    EXPECT_EQ(std::count(result->labels.data.begin(), result->labels.data.end(), 0),
              k.width * k.height);
  }
}

TEST(DepthSegmenter, EmptyDepthImageIsASizeError) {
  DepthSegmenter segmenter = makeSegmenter(Intrinsics::vga());
  StatusOr<SegmentationResult> result = segmenter.segment(DepthImage{});
  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_TRUE(contains(result.status().message(), "0x0")) << result.status();
  EXPECT_TRUE(contains(result.status().message(), "640x480")) << result.status();
}

TEST(DepthSegmenter, NonFiniteAndNegativeDepthsAreInvalidPixels) {
  const TwoBoxes world;
  const Intrinsics k = Intrinsics::vga();
  RenderOutput frame = render(k, world.instances(), world.camera());
  const float bad_values[] = {std::numeric_limits<float>::quiet_NaN(),
                              std::numeric_limits<float>::infinity(),
                              -std::numeric_limits<float>::infinity(),
                              -1.0f,
                              -0.0f,
                              0.0f};
  // Scattered single pixels and a block of each kind of bad value.
  size_t n_bad = 0;
  for (size_t i = 0; i < frame.depth.data.size(); i += 37) {
    frame.depth.data[i] = bad_values[(i / 37) % 6];
    ++n_bad;
  }
  for (int v = 200; v < 260; ++v) {
    for (int u = 100; u < 400; ++u) {
      float& d = frame.depth.at(u, v);
      if (isValidDepth(d)) ++n_bad;
      d = bad_values[size_t(u - 100) / 50];
    }
  }
  // Hole filling off: the scattered bad pixels would be filled from their neighbours.
  SegmentationParams no_fill;
  no_fill.fill_holes_iterations = 0;
  DepthSegmenter segmenter = makeSegmenter(k, no_fill);
  StatusOr<SegmentationResult> result = segmenter.segment(frame.depth, &frame.color);
  ASSERT_TRUE(result.ok()) << result.status();
  EXPECT_EQ(result->invalid_pixels, n_bad);
  EXPECT_FALSE(result->segments.empty());
  for (const Segment& s : result->segments) {
    for (size_t j = 0; j < s.pixels.size(); ++j) {
      ASSERT_TRUE(isValidDepth(frame.depth.data[s.pixels[j]])) << "pixel " << s.pixels[j];
      ASSERT_TRUE(s.points[j].allFinite());
      ASSERT_GT(s.points[j].z(), 0.0f);
      ASSERT_TRUE(s.normals[j].allFinite());
    }
  }
  for (size_t i = 0; i < frame.depth.data.size(); ++i) {
    if (!isValidDepth(frame.depth.data[i])) {
      ASSERT_EQ(result->labels.data[i], 0) << "pixel " << i;
    }
  }
}

TEST(DepthSegmenter, OnePixelImageDoesNotCrash) {
  const Intrinsics k{1, 1, 1.0, 1.0, 0.5, 0.5};
  DepthSegmenter segmenter = makeSegmenter(k);
  for (float d : {1.0f, 0.0f, std::numeric_limits<float>::quiet_NaN()}) {
    SegmentationMaps maps;
    StatusOr<SegmentationResult> result = segmenter.segment(DepthImage(1, 1, d), nullptr, &maps);
    ASSERT_TRUE(result.ok()) << result.status();
    EXPECT_LE(result->segments.size(), 1u);
    for (const Segment& s : result->segments) {
      for (const auto& p : s.points) EXPECT_TRUE(p.allFinite());
    }
  }
}

TEST(DepthSegmenter, OddImageSizesDoNotCrashAndKeepTheirShape) {
  const TwoBoxes world;
  for (const auto& [w, h] :
       std::vector<std::pair<int, int>>{{641, 479}, {333, 251}, {97, 61}, {3, 2}}) {
    const Intrinsics k{w, h, 525.0 * w / 640.0, 525.0 * w / 640.0, (w - 1) / 2.0, (h - 1) / 2.0};
    const RenderOutput frame = render(k, world.instances(), world.camera());
    DepthSegmenter segmenter = makeSegmenter(k);
    SegmentationMaps maps;
    StatusOr<SegmentationResult> result = segmenter.segment(frame.depth, &frame.color, &maps);
    ASSERT_TRUE(result.ok()) << w << "x" << h << ": " << result.status();
    EXPECT_EQ(result->labels.width, w);
    EXPECT_EQ(result->labels.height, h);
    EXPECT_EQ(maps.normals.width, w);
    EXPECT_EQ(maps.convexity.height, h);
    for (const Segment& s : result->segments) {
      for (uint32_t i : s.pixels) ASSERT_LT(i, uint32_t(w * h));
      for (const auto& p : s.points) ASSERT_TRUE(p.allFinite());
    }
  }
}

TEST(DepthSegmenter, TwoBoxesAt641x479GiveThreeSegments) {
  const TwoBoxes world;
  const Intrinsics k{641, 479, 525.0, 525.0, 320.0, 239.0};
  const RenderOutput frame = render(k, world.instances(), world.camera());
  DepthSegmenter segmenter = makeSegmenter(k);
  StatusOr<SegmentationResult> result = segmenter.segment(frame.depth, &frame.color);
  ASSERT_TRUE(result.ok()) << result.status();
  const Overlap overlap(result->labels, frame.instances);
  EXPECT_EQ(result->segments.size(), 3u) << overlap.describe();
  EXPECT_GE(overlap.coverage(kBoxA), 0.90) << overlap.describe();
  EXPECT_GE(overlap.coverage(kBoxB), 0.90) << overlap.describe();
}

// The paper's camera (Tango, 224×172): windows and the minimum size scale with the image, and
// the same scene must still give floor + two boxes.
TEST(DepthSegmenter, TwoBoxesAtTangoResolutionGiveThreeSegments) {
  const TwoBoxes world;
  const Intrinsics k = Intrinsics::tango();
  const RenderOutput frame = render(k, world.instances(), world.camera());
  DepthSegmenter segmenter = makeSegmenter(k);
  StatusOr<SegmentationResult> result = segmenter.segment(frame.depth, &frame.color);
  ASSERT_TRUE(result.ok()) << result.status();
  const Overlap overlap(result->labels, frame.instances);
  EXPECT_EQ(result->segments.size(), 3u) << overlap.describe();
  EXPECT_GE(overlap.coverage(kBoxA), 0.85) << overlap.describe();
  EXPECT_GE(overlap.coverage(kBoxB), 0.85) << overlap.describe();
  for (const Segment& s : result->segments) {
    EXPECT_GE(overlap.purity(s.label), 0.95) << "segment " << s.label << "\n" << overlap.describe();
  }
}

TEST(DepthSegmenter, DepthSizeDifferentFromIntrinsicsIsInvalidArgument) {
  DepthSegmenter segmenter = makeSegmenter(Intrinsics::vga());
  StatusOr<SegmentationResult> result = segmenter.segment(DepthImage(320, 240, 1.0f));
  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_TRUE(contains(result.status().message(), "320x240")) << result.status();
  EXPECT_TRUE(contains(result.status().message(), "640x480")) << result.status();
  EXPECT_TRUE(contains(result.status().message(), "depth")) << result.status();
}

TEST(DepthSegmenter, ColourSizeDifferentFromIntrinsicsIsInvalidArgument) {
  DepthSegmenter segmenter = makeSegmenter(Intrinsics::vga());
  const DepthImage depth(640, 480, 1.0f);
  const ColorImage color(641, 479);
  StatusOr<SegmentationResult> result = segmenter.segment(depth, &color);
  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_TRUE(contains(result.status().message(), "641x479")) << result.status();
  EXPECT_TRUE(contains(result.status().message(), "640x480")) << result.status();
}

TEST(DepthSegmenter, InvalidParamsAreRejectedNamingTheField) {
  struct Case {
    const char* field;
    void (*apply)(SegmentationParams*);
  };
  const Case cases[] = {
      {"normal_window_px", [](SegmentationParams* p) { p->normal_window_px = 4; }},
      {"normal_window_px", [](SegmentationParams* p) { p->normal_window_px = 1; }},
      {"min_segment_px", [](SegmentationParams* p) { p->min_segment_px = 0; }},
      {"discontinuity_threshold",
       [](SegmentationParams* p) { p->discontinuity_threshold = std::nanf(""); }},
      {"convexity_threshold", [](SegmentationParams* p) { p->convexity_threshold = 1.5f; }},
      {"fill_holes_iterations", [](SegmentationParams* p) { p->fill_holes_iterations = -1; }},
  };
  for (const Case& c : cases) {
    SegmentationParams params;
    c.apply(&params);
    StatusOr<DepthSegmenter> segmenter = DepthSegmenter::create(params, Intrinsics::vga());
    ASSERT_FALSE(segmenter.ok()) << c.field;
    EXPECT_EQ(segmenter.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_TRUE(contains(segmenter.status().message(), c.field)) << segmenter.status();
  }
  // Invalid intrinsics too.
  StatusOr<DepthSegmenter> segmenter =
      DepthSegmenter::create(SegmentationParams{}, Intrinsics{640, 480, 0.0, 525.0, 319.5, 239.5});
  ASSERT_FALSE(segmenter.ok());
  EXPECT_EQ(segmenter.status().code(), absl::StatusCode::kInvalidArgument);
}

// --- Segment contents ----------------------------------------------------------------------------

TEST(DepthSegmenter, SegmentsCarryBackProjectedPointsUnitNormalsAndMeanColour) {
  const TwoBoxes world;
  const Intrinsics k = Intrinsics::vga();
  const RenderOutput frame = render(k, world.instances(), world.camera());
  DepthSegmenter segmenter = makeSegmenter(k);
  StatusOr<SegmentationResult> result = segmenter.segment(frame.depth, &frame.color);
  ASSERT_TRUE(result.ok()) << result.status();
  ASSERT_FALSE(result->segments.empty());
  size_t labelled = 0;
  for (size_t si = 0; si < result->segments.size(); ++si) {
    const Segment& s = result->segments[si];
    EXPECT_EQ(s.label, int32_t(si + 1));
    ASSERT_EQ(s.points.size(), s.pixels.size());
    ASSERT_EQ(s.normals.size(), s.pixels.size());
    labelled += s.pixels.size();
    Eigen::Vector3d color_sum = Eigen::Vector3d::Zero();
    size_t no_normal = 0;
    std::string first_without;
    for (size_t j = 0; j < s.pixels.size(); ++j) {
      const uint32_t i = s.pixels[j];
      ASSERT_EQ(result->labels.data[i], s.label);
      const int u = int(i % uint32_t(k.width)), v = int(i / uint32_t(k.width));
      if (j % 101 == 0) {
        const Eigen::Vector3d expected = k.backProject(u, v, frame.depth.data[i]);
        EXPECT_LT((s.points[j].cast<double>() - expected).norm(), 1e-5 * expected.z())
            << "pixel " << u << "," << v;
      }
      const Eigen::Vector3f& n = s.normals[j];
      if (n.isZero()) {
        if (no_normal++ == 0) {
          first_without = absl::StrCat("(", u, ", ", v, ")");
        }
      } else {
        EXPECT_NEAR(n.norm(), 1.0f, 1e-4f) << "pixel " << u << "," << v;
        EXPECT_LT(n.dot(s.points[j]), 0.0f) << "pixel " << u << "," << v;
      }
      const Rgb8 c = frame.color.data[i];
      color_sum += Eigen::Vector3d(c.r, c.g, c.b);
    }
    EXPECT_EQ(no_normal, 0u) << "segment " << s.label << " has pixels without a normal, first at "
                             << first_without;
    ASSERT_TRUE(s.mean_color.has_value());
    const Eigen::Vector3d mean = color_sum / double(s.pixels.size());
    EXPECT_NEAR(s.mean_color->r, mean.x(), 0.51);
    EXPECT_NEAR(s.mean_color->g, mean.y(), 0.51);
    EXPECT_NEAR(s.mean_color->b, mean.z(), 0.51);
  }
  EXPECT_EQ(size_t(std::count_if(result->labels.data.begin(), result->labels.data.end(),
                                 [](int32_t l) { return l != 0; })),
            labelled);
  // Without a colour image there is no mean colour.
  result = segmenter.segment(frame.depth);
  ASSERT_TRUE(result.ok());
  for (const Segment& s : result->segments) EXPECT_FALSE(s.mean_color.has_value());
}

// The segmenter keeps scratch buffers between frames: a frame's result must not depend on the
// frames before it (different content, different amounts of invalid depth).
TEST(DepthSegmenter, ReusedSegmenterGivesTheSameResultAsAFreshOne) {
  const TwoBoxes world;
  const Intrinsics k = Intrinsics::vga();
  const RenderOutput first = render(k, world.instances(), world.camera());
  const sim::DepthNoiseParams noise;
  const RenderOutput second =
      render(k, world.instances(), cameraLookingDown({0.1, 0.1, 0.1}, 1.3, 50.0), &noise);
  DepthSegmenter reused = makeSegmenter(k);
  ASSERT_TRUE(reused.segment(first.depth, &first.color).ok());
  ASSERT_TRUE(reused.segment(DepthImage(k.width, k.height, 0.0f)).ok());
  StatusOr<SegmentationResult> a = reused.segment(second.depth, &second.color);
  DepthSegmenter fresh = makeSegmenter(k);
  StatusOr<SegmentationResult> b = fresh.segment(second.depth, &second.color);
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_TRUE(a->labels == b->labels);
  ASSERT_EQ(a->segments.size(), b->segments.size());
  EXPECT_EQ(a->invalid_pixels, b->invalid_pixels);
  EXPECT_EQ(a->boundary_pixels, b->boundary_pixels);
  EXPECT_EQ(a->dropped_small, b->dropped_small);
  for (size_t i = 0; i < a->segments.size(); ++i) {
    EXPECT_EQ(a->segments[i].pixels, b->segments[i].pixels);
    EXPECT_EQ(a->segments[i].normals, b->segments[i].normals);
  }
}

// Differential test: components, size filter and label growth against the slow reference in
// tests/support, on the boundary map the segmenter itself produced.
TEST(DepthSegmenter, LabelsMatchASlowReferenceOnTheSameBoundaries) {
  const TwoBoxes world;
  const Intrinsics k = Intrinsics::vga();
  const sim::DepthNoiseParams noise;
  const std::vector<RenderOutput> frames = {
      render(k, world.instances(), world.camera()),
      render(k, world.instances(), world.camera(), &noise),
      render(k, world.instances(), cameraLookingDown({0.1, 0.1, 0.1}, 1.3, 50.0), &noise)};
  const SegmentationParams params;
  DepthSegmenter segmenter = makeSegmenter(k, params);
  for (size_t f = 0; f < frames.size(); ++f) {
    SegmentationMaps maps;
    StatusOr<SegmentationResult> result = segmenter.segment(frames[f].depth, nullptr, &maps);
    ASSERT_TRUE(result.ok()) << result.status();
    Image<uint8_t> has_normal(maps.normals.width, maps.normals.height, 0);
    for (size_t i = 0; i < has_normal.size(); ++i) has_normal.data[i] = !maps.normals.data[i].isZero();
    const testing::ReferenceLabels reference = testing::referenceLabels(
        maps.boundaries, maps.depth, has_normal, k, segmenter.minSegmentPixels(),
        params.label_growth_iterations, params.max_label_growth_distance_m);
    EXPECT_EQ(int32_t(result->segments.size()), reference.segments) << "frame " << f;
    EXPECT_EQ(result->dropped_small, reference.dropped_small) << "frame " << f;
    // Label numbers may differ: map each segment to the reference label it overlaps most.
    std::map<int32_t, std::map<int32_t, size_t>> pairs;
    for (size_t i = 0; i < reference.labels.size(); ++i) {
      ++pairs[result->labels.data[i]][reference.labels.data[i]];
    }
    std::map<int32_t, int32_t> to_reference;
    std::set<int32_t> used;
    for (const auto& [label, counts] : pairs) {
      const auto best =
          std::max_element(counts.begin(), counts.end(),
                           [](const auto& a, const auto& b) { return a.second < b.second; });
      to_reference[label] = best->first;
      EXPECT_TRUE(used.insert(best->first).second)
          << "frame " << f << ": two segments map to reference label " << best->first;
    }
    size_t mismatched = 0, ties = 0, first = 0;
    for (size_t i = 0; i < reference.labels.size(); ++i) {
      ties += reference.tie.data[i];
      if (to_reference[result->labels.data[i]] != reference.labels.data[i] &&
          !reference.tie.data[i]) {
        if (mismatched++ == 0) first = i;
      }
    }
    EXPECT_EQ(mismatched, 0u) << "frame " << f << ", first at pixel " << first << " ("
                              << first % size_t(k.width) << ", " << first / size_t(k.width) << "), "
                              << ties << " ties";
  }
}

TEST(DepthSegmenter, MapsAndCountsDescribeTheRun) {
  const TwoBoxes world;
  const Intrinsics k = Intrinsics::vga();
  const RenderOutput frame = render(k, world.instances(), world.camera());
  DepthSegmenter segmenter = makeSegmenter(k);
  SegmentationMaps maps;
  StatusOr<SegmentationResult> result = segmenter.segment(frame.depth, nullptr, &maps);
  ASSERT_TRUE(result.ok()) << result.status();
  EXPECT_EQ(maps.depth.size(), size_t(k.width * k.height));
  EXPECT_EQ(maps.discontinuities.size(), size_t(k.width * k.height));
  EXPECT_EQ(maps.normals.size(), size_t(k.width * k.height));
  EXPECT_EQ(maps.convexity.size(), size_t(k.width * k.height));
  EXPECT_EQ(maps.boundaries.size(), size_t(k.width * k.height));
  for (float c : maps.convexity.data) ASSERT_TRUE(c >= -1.0f && c <= 1.0f) << c;
  // Every labelled pixel is valid and every valid pixel is labelled or counted as boundary.
  size_t labelled = 0;
  for (const Segment& s : result->segments) labelled += s.pixels.size();
  EXPECT_EQ(labelled + result->boundary_pixels + result->invalid_pixels,
            size_t(k.width * k.height));
  EXPECT_GE(result->timings.total_ms, 0.0);
}

}  // namespace
}  // namespace objdb::segmentation
