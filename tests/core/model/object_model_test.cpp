#include "core/model/object_model.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <numeric>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "core/model/features.h"
#include "tests/support/sdf_grid.h"

namespace objdb::model {
namespace {

using objdb::testing::boxSdf;
using objdb::testing::cylinderSdf;
using objdb::testing::Sdf;
using objdb::testing::sdfGrid;
using objdb::testing::sphereSdf;
using objdb::testing::unionSdf;
using ::testing::HasSubstr;

constexpr float kVoxel = 0.01f;

ModelBuildParams defaults() { return ModelBuildParams{}; }

TEST(SurfaceCloud, SphereSurfaceWithOutwardNormals) {
  const Eigen::Vector3f centre(0.1f, -0.2f, 0.3f);
  const float radius = 0.15f;
  const Eigen::Vector3f reach = Eigen::Vector3f::Constant(radius + 0.05f);
  auto grid = sdfGrid(sphereSdf(centre, radius), centre - reach, centre + reach, kVoxel,
                      3 * kVoxel);
  auto cloud = surfaceCloud(grid.layer, grid.surface_voxels, 3.0f);
  ASSERT_TRUE(cloud.ok()) << cloud.status();
  ASSERT_GT(cloud->points.size(), 1000u);
  ASSERT_EQ(cloud->normals.size(), cloud->points.size());
  double worst_radius = 0, worst_angle = 0;
  for (size_t i = 0; i < cloud->points.size(); ++i) {
    const Eigen::Vector3f r = cloud->points[i] - centre;
    worst_radius = std::max(worst_radius, double(std::abs(r.norm() - radius)));
    const double cosine = double(cloud->normals[i].dot(r.normalized()));
    worst_angle = std::max(worst_angle, std::acos(std::clamp(cosine, -1.0, 1.0)) * 180 / M_PI);
  }
  EXPECT_LT(worst_radius, 0.002);  // vertices on the sphere within 2 mm at 1 cm voxels
  EXPECT_LT(worst_angle, 10.0);    // and normals point outward
}

// The cloud carries the grid's colours (issue 47: every object's cloud came without them): a
// sphere red on one side, blue on the other.
TEST(SurfaceCloud, CarriesTheGridsColours) {
  const Eigen::Vector3f centre(0.0f, 0.0f, 0.0f);
  const float radius = 0.15f;
  const Eigen::Vector3f reach = Eigen::Vector3f::Constant(radius + 0.05f);
  auto grid = sdfGrid(sphereSdf(centre, radius), centre - reach, centre + reach, kVoxel,
                      3 * kVoxel);
  std::vector<tsdf::BlockIndex> blocks;
  for (const auto& [index, block] : grid.layer.blocks()) blocks.push_back(index);
  const int vps = grid.layer.voxelsPerSide();
  for (const auto& b : blocks) {
    for (int z = 0; z < vps; ++z) {
      for (int y = 0; y < vps; ++y) {
        for (int x = 0; x < vps; ++x) {
          const tsdf::VoxelIndex v = b * vps + tsdf::VoxelIndex(x, y, z);
          tsdf::TsdfVoxel* voxel = grid.layer.voxel(v);
          const bool left = grid.layer.voxelCenter(v).x() < centre.x();
          voxel->color = left ? Rgb8{200, 10, 10} : Rgb8{10, 10, 200};
        }
      }
    }
  }
  auto cloud = surfaceCloud(grid.layer, grid.surface_voxels, 3.0f);
  ASSERT_TRUE(cloud.ok()) << cloud.status();
  ASSERT_EQ(cloud->colors.size(), cloud->points.size());
  size_t checked = 0;
  for (size_t i = 0; i < cloud->points.size(); ++i) {
    const float x = cloud->points[i].x() - centre.x();
    if (std::abs(x) < 2 * kVoxel) continue;  // near the seam colours mix
    const Rgb8 want = x < 0 ? Rgb8{200, 10, 10} : Rgb8{10, 10, 200};
    ASSERT_EQ(cloud->colors[i].r, want.r) << i;
    ASSERT_EQ(cloud->colors[i].b, want.b) << i;
    ++checked;
  }
  EXPECT_GT(checked, 1000u);
}

TEST(SurfaceCloud, KeepsOnlyTheSegmentsVoxels) {
  // Two spheres in one grid; the segment is the first one's voxels only.
  const Eigen::Vector3f a(0, 0, 0), b(0.5f, 0, 0);
  auto both = sdfGrid(unionSdf({sphereSdf(a, 0.1f), sphereSdf(b, 0.1f)}),
                      Eigen::Vector3f(-0.2f, -0.2f, -0.2f), Eigen::Vector3f(0.7f, 0.2f, 0.2f),
                      kVoxel, 3 * kVoxel);
  std::vector<tsdf::VoxelIndex> first;
  for (const auto& v : both.surface_voxels) {
    if (both.layer.voxelCenter(v).x() < 0.25f) first.push_back(v);
  }
  auto cloud = surfaceCloud(both.layer, first, 3.0f);
  ASSERT_TRUE(cloud.ok());
  ASSERT_FALSE(cloud->points.empty());
  for (const auto& p : cloud->points) ASSERT_LT((p - a).norm(), 0.12f);
}

// A mug on a counter: the segment is the voxels nearer the mug than the counter (what the GSM's
// labels hold), and its cloud is the mug alone. Marching-cubes cells that merely touch a foot voxel
// also hold the counter's surface around the foot; keeping those vertices put a ring of counter
// top into every model of a small object on a support (2026-12-07: 10–23 % of a mug's points).
TEST(SurfaceCloud, AnObjectOnASupportKeepsNoRingOfTheSupport) {
  const Eigen::Vector3f axis(0.02f, -0.03f, 0.0f);
  const float radius = 0.04f, top = 0.0f, height = 0.1f;
  const Sdf counter = boxSdf({0, 0, top - 0.1f}, {0.3f, 0.3f, 0.1f});
  const Sdf mug = cylinderSdf(axis + Eigen::Vector3f(0, 0, top + height / 2), radius, height / 2);
  auto grid = sdfGrid(unionSdf({counter, mug}), Eigen::Vector3f(-0.2f, -0.2f, -0.1f),
                      Eigen::Vector3f(0.2f, 0.2f, 0.2f), kVoxel, 3 * kVoxel);
  std::vector<tsdf::VoxelIndex> segment;
  for (const auto& v : grid.surface_voxels) {
    const Eigen::Vector3f c = grid.layer.voxelCenter(v);
    if (mug(c) < counter(c)) segment.push_back(v);
  }
  auto cloud = surfaceCloud(grid.layer, segment, 3.0f);
  ASSERT_TRUE(cloud.ok()) << cloud.status();
  ASSERT_GT(cloud->points.size(), 300u);
  size_t ring = 0;
  for (const auto& p : cloud->points) {
    // On the counter's top, and off the mug's wall by more than a voxel (the crease at the foot
    // is both).
    const float off_wall = (p - axis).head<2>().norm() - radius;
    if (std::abs(p.z() - top) < 0.25f * kVoxel && off_wall > kVoxel) ++ring;
  }
  EXPECT_EQ(ring, 0u) << "of " << cloud->points.size() << " points";
}

TEST(SurfaceCloud, RejectsAnEmptySegment) {
  auto grid = sdfGrid(sphereSdf({0, 0, 0}, 0.1f), Eigen::Vector3f::Constant(-0.2f),
                      Eigen::Vector3f::Constant(0.2f), kVoxel, 3 * kVoxel);
  EXPECT_THAT(std::string(surfaceCloud(grid.layer, {}, 3.0f).status().message()),
              HasSubstr("no voxels"));
}

TEST(BuildModel, APlanarSegmentIsFlaggedAndNotDescribed) {
  // A 40 × 40 cm slab face: the segment is the voxels near its top face.
  auto grid = sdfGrid(boxSdf({0, 0, 0}, {0.2f, 0.2f, 0.05f}), Eigen::Vector3f(-0.3f, -0.3f, -0.1f),
                      Eigen::Vector3f(0.3f, 0.3f, 0.1f), kVoxel, 3 * kVoxel);
  std::vector<tsdf::VoxelIndex> top;
  for (const auto& v : grid.surface_voxels) {
    const Eigen::Vector3f c = grid.layer.voxelCenter(v);
    if (c.z() > 0.03f && std::abs(c.x()) < 0.17f && std::abs(c.y()) < 0.17f) top.push_back(v);
  }
  auto model = buildModel(std::move(grid.layer), top, defaults());
  ASSERT_TRUE(model.ok()) << model.status();
  EXPECT_TRUE(model->planar);
  EXPECT_GT(model->plane_inlier_ratio, 0.95f);
  EXPECT_TRUE(model->keypoint_indices.empty());
  EXPECT_TRUE(model->descriptors.empty());
  EXPECT_FALSE(model->matchable(ModelParams{}));
}

// How near a salient keypoint lies to the corner or edge that makes it salient (voxels are 1 cm;
// r_H is 3 cm).
constexpr float kCornerRadius = 0.04f;
constexpr float kEdgeRadius = 0.04f;

TEST(BuildModel, ABoxGetsKeypointsAtItsCornersAndDescriptors) {
  auto grid = sdfGrid(boxSdf({0, 0, 0}, {0.2f, 0.15f, 0.1f}), Eigen::Vector3f::Constant(-0.3f),
                      Eigen::Vector3f::Constant(0.3f), kVoxel, 3 * kVoxel);
  auto model = buildModel(std::move(grid.layer), grid.surface_voxels, defaults());
  ASSERT_TRUE(model.ok()) << model.status();
  EXPECT_FALSE(model->planar);
  EXPECT_LT(model->plane_inlier_ratio, 0.5f);
  ASSERT_TRUE(model->matchable(ModelParams{}));
  ASSERT_EQ(model->descriptors.size(), model->keypoint_indices.size());
  EXPECT_GE(model->keypoint_indices.size(), 8u);
  // ISS ∪ Harris3D alone (uniform_spacing_m would put a point within 5 cm of anything): some
  // keypoint sits near each of the 8 corners, and none lies in the middle of a face.
  KeypointParams detectors;
  detectors.uniform_spacing_m = 0.0f;
  const std::vector<uint32_t> salient = detectKeypoints(model->cloud, detectors);
  ASSERT_FALSE(salient.empty());
  for (int c = 0; c < 8; ++c) {
    const Eigen::Vector3f corner((c & 1) ? 0.2f : -0.2f, (c & 2) ? 0.15f : -0.15f,
                                 (c & 4) ? 0.1f : -0.1f);
    float nearest = INFINITY;
    for (const uint32_t i : salient) {
      nearest = std::min(nearest, (model->cloud.points[i] - corner).norm());
    }
    EXPECT_LT(nearest, kCornerRadius) << "corner " << corner.transpose();
  }
  for (const uint32_t i : salient) {
    // Distance to the nearest edge of the box: a face's middle is far from all of them.
    const Eigen::Vector3f p = model->cloud.points[i].cwiseAbs();
    const Eigen::Vector3f half(0.2f, 0.15f, 0.1f);
    const Eigen::Vector3f gap = (half - p).cwiseAbs();
    std::array<float, 3> g = {gap.x(), gap.y(), gap.z()};
    std::sort(g.begin(), g.end());
    EXPECT_LT(g[1], kEdgeRadius) << "keypoint at " << model->cloud.points[i].transpose()
                                 << " is on no edge";
  }
  // FPFH: three 11-bin sub-histograms, each normalised to 100.
  for (const Fpfh& d : model->descriptors) {
    const float sum = std::accumulate(d.begin(), d.end(), 0.0f);
    ASSERT_NEAR(sum, 300.0f, 1.0f);
  }
  EXPECT_GT(model->timings.descriptors_ms, 0.0);
}

// uniform_spacing_m adds the point nearest each cube's centre to ISS ∪ Harris3D: on a box of
// 0.4 × 0.3 × 0.2 m (0.52 m² of surface) with 5 cm cubes, one keypoint per occupied cube.
TEST(DetectKeypoints, UniformSpacingAddsOnePointPerOccupiedCube) {
  auto grid = sdfGrid(boxSdf({0, 0, 0}, {0.2f, 0.15f, 0.1f}), Eigen::Vector3f::Constant(-0.3f),
                      Eigen::Vector3f::Constant(0.3f), kVoxel, 3 * kVoxel);
  auto model = buildModel(std::move(grid.layer), grid.surface_voxels, defaults());
  ASSERT_TRUE(model.ok()) << model.status();
  KeypointParams params;
  params.uniform_spacing_m = 0.0f;  // ISS ∪ Harris3D alone
  KeypointCounts plain_counts, uniform_counts;
  const auto plain = detectKeypoints(model->cloud, params, &plain_counts);
  params.uniform_spacing_m = 0.05f;
  const auto uniform = detectKeypoints(model->cloud, params, &uniform_counts);
  EXPECT_EQ(plain_counts.uniform, 0u);
  EXPECT_EQ(uniform.size(), plain.size() + uniform_counts.uniform);
  EXPECT_TRUE(std::includes(uniform.begin(), uniform.end(), plain.begin(), plain.end()));
  EXPECT_TRUE(std::is_sorted(uniform.begin(), uniform.end()));
  // Occupied 5 cm cubes of the box surface: between area / spacing² and twice that.
  EXPECT_GE(uniform_counts.uniform + plain.size(), size_t(0.52 / 0.0025 * 0.8));
  EXPECT_LE(uniform.size(), size_t(2 * 0.52 / 0.0025) + plain.size());
  // Every cloud point lies within one cube diagonal of a keypoint.
  for (const auto& p : model->cloud.points) {
    float nearest = INFINITY;
    for (uint32_t k : uniform) nearest = std::min(nearest, (model->cloud.points[k] - p).norm());
    ASSERT_LT(nearest, 0.05f * std::sqrt(3.0f));
  }
  EXPECT_EQ(detectKeypoints(model->cloud, params), uniform);  // deterministic
}

// descriptors.surface_spacing_m builds the histograms over a resampled cloud: one descriptor per
// keypoint still, each a valid FPFH (three sub-histograms of 100). That they still match across
// views is checked in tests/core/matching/registration_test.cpp.
TEST(ComputeFpfh, OverAResampledSurfaceKeepsEveryKeypoint) {
  auto grid = sdfGrid(boxSdf({0, 0, 0}, {0.2f, 0.15f, 0.1f}), Eigen::Vector3f::Constant(-0.3f),
                      Eigen::Vector3f::Constant(0.3f), kVoxel, 3 * kVoxel);
  auto model = buildModel(std::move(grid.layer), grid.surface_voxels, defaults());
  ASSERT_TRUE(model.ok()) << model.status();
  std::vector<uint32_t> full_keys = model->keypoint_indices, coarse_keys = model->keypoint_indices;
  DescriptorParams params;
  params.surface_spacing_m = 0.0f;  // the model cloud itself
  const auto full = computeFpfh(model->cloud, &full_keys, params);
  params.surface_spacing_m = 0.02f;
  const auto coarse = computeFpfh(model->cloud, &coarse_keys, params, 2);
  ASSERT_EQ(coarse_keys, model->keypoint_indices);
  ASSERT_EQ(coarse.size(), full.size());
  for (const Fpfh& d : coarse) {
    ASSERT_NEAR(std::accumulate(d.begin(), d.end(), 0.0f), 300.0f, 1.0f);
  }
  EXPECT_NE(coarse, full);  // the option does something
}

TEST(BuildModel, IsDeterministic) {
  auto make = [] {
    auto grid = sdfGrid(unionSdf({boxSdf({0, 0, 0}, {0.15f, 0.1f, 0.1f}),
                                  sphereSdf({0.15f, 0.1f, 0.1f}, 0.08f)}),
                        Eigen::Vector3f::Constant(-0.3f), Eigen::Vector3f::Constant(0.35f), kVoxel,
                        3 * kVoxel);
    return buildModel(std::move(grid.layer), grid.surface_voxels, defaults()).value();
  };
  const ObjectModel a = make(), b = make();
  EXPECT_EQ(a.keypoint_indices, b.keypoint_indices);
  EXPECT_EQ(a.descriptors, b.descriptors);
  EXPECT_EQ(a.cloud.points, b.cloud.points);
}

// Keypoints and descriptors on several threads (OpenMP inside ISS, Harris3D and FPFH) equal the
// single-threaded ones, bit for bit, uniform keypoints included.
TEST(BuildModel, ThreadsDoNotChangeTheResult) {
  auto make = [](int threads) {
    auto grid = sdfGrid(unionSdf({boxSdf({0, 0, 0}, {0.15f, 0.1f, 0.1f}),
                                  sphereSdf({0.15f, 0.1f, 0.1f}, 0.08f)}),
                        Eigen::Vector3f::Constant(-0.3f), Eigen::Vector3f::Constant(0.35f), kVoxel,
                        3 * kVoxel);
    ModelBuildParams params = defaults();
    params.keypoints.uniform_spacing_m = 0.05f;
    params.threads = threads;
    return buildModel(std::move(grid.layer), grid.surface_voxels, params).value();
  };
  const ObjectModel one = make(1), three = make(3);
  ASSERT_GT(one.keypoint_indices.size(), 10u);
  EXPECT_EQ(one.keypoint_indices, three.keypoint_indices);
  EXPECT_EQ(one.descriptors, three.descriptors);
}

TEST(BuildModel, BadInputIsAClearError) {
  auto grid = sdfGrid(sphereSdf({0, 0, 0}, 0.1f), Eigen::Vector3f::Constant(-0.2f),
                      Eigen::Vector3f::Constant(0.2f), kVoxel, 3 * kVoxel);
  ModelBuildParams bad = defaults();
  bad.descriptors.fpfh_radius_m = -1.0f;
  EXPECT_THAT(std::string(buildModel(std::move(grid.layer), grid.surface_voxels, bad)
                              .status()
                              .message()),
              HasSubstr("descriptors.fpfh_radius_m"));
  // Voxels that hold no zero crossing: all far outside the sphere.
  auto far = sdfGrid(sphereSdf({0, 0, 0}, 0.1f), Eigen::Vector3f::Constant(-0.2f),
                     Eigen::Vector3f::Constant(0.2f), kVoxel, 3 * kVoxel);
  const auto status =
      buildModel(std::move(far.layer), {tsdf::VoxelIndex(30, 30, 30)}, defaults()).status();
  EXPECT_EQ(status.code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_THAT(std::string(status.message()), HasSubstr("hold no surface"));
}

TEST(ResampleCloud, OnePointPerCubeWithMeanPositionAndNormal) {
  PointCloud cloud;
  cloud.points = {{0.001f, 0.001f, 0.001f}, {0.003f, 0.005f, 0.007f}, {0.015f, 0.0f, 0.0f}};
  cloud.normals = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  const PointCloud out = resampleCloud(cloud, 0.01f);
  ASSERT_EQ(out.points.size(), 2u);
  ASSERT_EQ(out.normals.size(), 2u);
  // The first cube holds the first two points.
  const size_t first = out.points[0].x() < 0.01f ? 0 : 1;
  EXPECT_TRUE(out.points[first].isApprox(Eigen::Vector3f(0.002f, 0.003f, 0.004f), 1e-5f));
  EXPECT_TRUE(out.normals[first].isApprox(Eigen::Vector3f(1, 1, 0).normalized(), 1e-5f));
  EXPECT_TRUE(out.normals[1 - first].isApprox(Eigen::Vector3f(0, 0, 1)));
  EXPECT_TRUE(out.colors.empty());  // none given
  // Colours: the mean of the cube's.
  cloud.colors = {{10, 20, 30}, {20, 41, 60}, {200, 0, 0}};
  const PointCloud coloured = resampleCloud(cloud, 0.01f);
  ASSERT_EQ(coloured.colors.size(), 2u);
  EXPECT_EQ(coloured.colors[first].r, 15);
  EXPECT_EQ(coloured.colors[first].g, 31);  // 30.5 rounds up
  EXPECT_EQ(coloured.colors[first].b, 45);
  EXPECT_EQ(coloured.colors[1 - first].r, 200);
  // Opposite normals cancel: that cube has no usable normal and is dropped.
  PointCloud flat;
  flat.points = {{0.001f, 0, 0}, {0.002f, 0, 0}};
  flat.normals = {{0, 0, 1}, {0, 0, -1}};
  EXPECT_TRUE(resampleCloud(flat, 0.01f).points.empty());
}

TEST(FitPlane, RecoversAKnownPlane) {
  PointCloud cloud;
  for (int i = 0; i < 30; ++i) {
    for (int j = 0; j < 30; ++j) {
      const float x = i * 0.01f, y = j * 0.01f;
      cloud.points.emplace_back(x, y, 0.5f * x + 0.1f);  // z = 0.5 x + 0.1
    }
  }
  cloud.points.emplace_back(0.1f, 0.1f, 2.0f);  // one outlier
  const PlaneFit fit = fitPlane(cloud, 0.005f, 100);
  const Eigen::Vector3f n = fit.coefficients.head<3>();
  EXPECT_NEAR(std::abs(n.dot(Eigen::Vector3f(-0.5f, 0, 1).normalized())), 1.0f, 1e-4f);
  EXPECT_NEAR(fit.inlier_ratio, 900.0f / 901.0f, 1e-6f);
  EXPECT_EQ(fitPlane(PointCloud{}, 0.01f, 10).inlier_ratio, 0.0f);
}

}  // namespace
}  // namespace objdb::model
