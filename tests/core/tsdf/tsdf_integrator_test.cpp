#include "core/tsdf/tsdf_integrator.h"

#include <cmath>

#include <gtest/gtest.h>

#include "core/sim/renderer.h"
#include "core/sim/shapes.h"

namespace objdb::tsdf {
namespace {

TsdfParams params2cm() {
  TsdfParams p;
  p.voxel_size_m = 0.02f;
  p.voxels_per_side = 8;
  p.truncation_voxels = 3.0f;
  return p;
}

TEST(TsdfIntegrator, FrontalPlaneMatchesAnalyticSignedDistance) {
  const Intrinsics k = Intrinsics::vga();
  const TsdfParams params = params2cm();
  TsdfLayer layer = TsdfLayer::create(params.voxel_size_m, params.voxels_per_side).value();
  const auto integrator = TsdfIntegrator::create(params, k).value();
  const DepthImage depth(k.width, k.height, 2.0f);
  auto stats = integrator.integrate(depth, Transform::Identity(), &layer);
  ASSERT_TRUE(stats.ok()) << stats.status();
  EXPECT_EQ(stats->points_used, size_t(k.width) * k.height);
  EXPECT_GT(stats->voxels_updated, 0u);
  const float trunc = params.truncationDistance();
  size_t checked = 0;
  for (const auto& [index, block] : layer.blocks()) {
    for (int z = 0; z < 8; ++z) {
      for (int y = 0; y < 8; ++y) {
        for (int x = 0; x < 8; ++x) {
          const VoxelIndex v = index * 8 + Eigen::Vector3i(x, y, z);
          const TsdfVoxel& voxel = *layer.voxel(v);
          if (!(voxel.weight > 0.0f)) continue;
          const float truth = 2.0f - layer.voxelCenter(v).z();
          ASSERT_GE(truth, -trunc - 1e-5f) << "a voxel hidden behind the plane was updated";
          ASSERT_NEAR(voxel.distance, std::min(truth, trunc), 1e-5f);
          ++checked;
        }
      }
    }
  }
  EXPECT_GT(checked, 10000u);
  float d = 0.0f;
  ASSERT_TRUE(layer.interpolateDistance({0.0f, 0.0f, 1.99f}, &d));
  EXPECT_NEAR(d, 0.01f, 1e-5f);
}

TEST(TsdfIntegrator, CarvingObservesTheFreeSpaceInFrontOfTheBand) {
  const Intrinsics k = Intrinsics::vga();
  TsdfParams params = params2cm();
  const DepthImage depth(k.width, k.height, 2.0f);  // a wall 2 m in front of the camera
  auto observedAt = [&](float carve, float z, float* distance) {
    params.carve_distance_m = carve;
    TsdfLayer layer = TsdfLayer::create(params.voxel_size_m, params.voxels_per_side).value();
    EXPECT_TRUE(
        TsdfIntegrator::create(params, k).value().integrate(depth, Transform::Identity(), &layer).ok());
    const TsdfVoxel* voxel = layer.voxel(layer.voxelIndexOf({0.0f, 0.0f, z}));
    if (voxel == nullptr || !(voxel->weight > 0.0f)) return false;
    *distance = voxel->distance;
    return true;
  };
  const float trunc = params.truncationDistance();
  float d = 0.0f;
  // Without carving, 30 cm in front of the wall lies outside every allocated block.
  EXPECT_FALSE(observedAt(0.0f, 1.7f, &d));
  // With 40 cm of carving it is observed as free space, and nothing moves at the wall.
  ASSERT_TRUE(observedAt(0.4f, 1.7f, &d));
  EXPECT_NEAR(d, trunc, 1e-6f);
  ASSERT_TRUE(observedAt(0.4f, 1.99f, &d));
  EXPECT_NEAR(d, 0.01f, 1e-5f);
  // Beyond the carving distance (and the block it ends in) nothing is allocated.
  EXPECT_FALSE(observedAt(0.4f, 1.0f, &d));
}

TEST(TsdfIntegrator, SphereSeenFromAroundMatchesItsSignedDistance) {
  const Intrinsics k = Intrinsics::vga();
  const TsdfParams params = params2cm();
  TsdfLayer layer = TsdfLayer::create(params.voxel_size_m, params.voxels_per_side).value();
  const auto integrator = TsdfIntegrator::create(params, k).value();
  const float radius = 0.3f;
  const Eigen::Vector3f centre(0.1f, -0.2f, 1.0f);
  const TriangleMesh sphere = sim::makeSphere(radius, 96, 192);
  Transform T_world_sphere = Transform::Identity();
  T_world_sphere.translation() = centre.cast<double>();
  const sim::Renderer renderer(k);
  sim::RenderOutput out;
  for (int view = 0; view < 8; ++view) {
    const double a = view * M_PI / 4;
    const Eigen::Vector3d eye = centre.cast<double>() +
                                Eigen::Vector3d(1.4 * std::cos(a), 1.4 * std::sin(a), 0.5);
    const Transform T_world_camera = lookAt(eye, centre.cast<double>()).value();
    renderer.render({sim::RenderInstance{&sphere, T_world_sphere, 1}}, T_world_camera, &out);
    ASSERT_TRUE(integrator.integrate(out.depth, T_world_camera, &layer).ok());
  }
  // Projective distances are measured along the view axis: a view at angle θ to the surface
  // normal reports |d| / cos θ, so near-surface magnitudes are overestimated by oblique views
  // while signs and the zero crossing stay right. Check signs strictly, magnitudes loosely.
  double sum_error = 0.0;
  size_t near = 0, signed_checked = 0, wrong_sign = 0;
  for (const auto& [index, block] : layer.blocks()) {
    for (size_t i = 0; i < block->voxels().size(); ++i) {
      const TsdfVoxel& voxel = block->voxels()[i];
      if (!(voxel.weight > 0.0f)) continue;
      const int x = int(i % 8), y = int((i / 8) % 8), z = int(i / 64);
      const float truth =
          (layer.voxelCenter(index * 8 + Eigen::Vector3i(x, y, z)) - centre).norm() - radius;
      if (std::abs(truth) > 0.5f * params.voxel_size_m && std::abs(truth) < 2 * params.voxel_size_m) {
        ++signed_checked;
        wrong_sign += (voxel.distance > 0.0f) != (truth > 0.0f);
      }
      if (std::abs(truth) > params.voxel_size_m) continue;
      sum_error += std::abs(voxel.distance - truth);
      ++near;
    }
  }
  EXPECT_GT(near, 2000u);
  EXPECT_GT(signed_checked, 5000u);
  // Only at the limb, where the nearest pixel of a voxel can see past the silhouette edge.
  EXPECT_LT(wrong_sign, signed_checked / 200) << wrong_sign << " of " << signed_checked;
  EXPECT_LT(sum_error / double(near), 0.6 * params.voxel_size_m);
  // The zero crossing lies on the sphere wherever it was seen.
  int on_surface = 0;
  for (int i = 0; i < 200; ++i) {
    const double theta = M_PI * (0.3 + 0.4 * (i % 20) / 20.0), phi = 2 * M_PI * i / 200.0;
    const Eigen::Vector3f p = centre + radius * Eigen::Vector3f(std::sin(theta) * std::cos(phi),
                                                                std::sin(theta) * std::sin(phi),
                                                                std::cos(theta));
    float d = 0.0f;
    if (!layer.interpolateDistance(p, &d)) continue;
    ++on_surface;
    EXPECT_NEAR(d, 0.0f, 0.35f * params.voxel_size_m);
  }
  EXPECT_GT(on_surface, 150);
}

TEST(TsdfIntegrator, BadPosesAndSizesAreRefusedAndLeaveTheMapUntouched) {
  const Intrinsics k = Intrinsics::tango();
  const TsdfParams params = params2cm();
  TsdfLayer layer = TsdfLayer::create(params.voxel_size_m, params.voxels_per_side).value();
  const auto integrator = TsdfIntegrator::create(params, k).value();
  const DepthImage depth(k.width, k.height, 1.5f);
  Transform nan_pose = Transform::Identity();
  nan_pose.translation().x() = std::nan("");
  auto r = integrator.integrate(depth, nan_pose, &layer);
  EXPECT_EQ(r.status().code(), absl::StatusCode::kInvalidArgument);
  Transform sheared = Transform::Identity();
  sheared.linear()(0, 1) = 0.2;
  r = integrator.integrate(depth, sheared, &layer);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("orthonormal"), absl::string_view::npos);
  r = integrator.integrate(DepthImage(640, 480, 1.0f), Transform::Identity(), &layer);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("640x480"), absl::string_view::npos);
  TsdfLayer other = TsdfLayer::create(0.01f, 8).value();
  EXPECT_FALSE(integrator.integrate(depth, Transform::Identity(), &other).ok());
  EXPECT_EQ(layer.numBlocks(), 0u);
  EXPECT_EQ(other.numBlocks(), 0u);
  TsdfParams bad = params;
  bad.voxel_size_m = 5.0f;
  auto created = TsdfIntegrator::create(bad, k);
  ASSERT_FALSE(created.ok());
  EXPECT_NE(created.status().message().find("tsdf.voxel_size_m"), absl::string_view::npos);
}

TEST(TsdfIntegrator, InvalidAndOutOfRangeDepthsAreSkippedAndCounted) {
  const Intrinsics k = Intrinsics::tango();
  const TsdfParams params = params2cm();
  TsdfLayer with_bad = TsdfLayer::create(params.voxel_size_m, params.voxels_per_side).value();
  TsdfLayer clean = TsdfLayer::create(params.voxel_size_m, params.voxels_per_side).value();
  const auto integrator = TsdfIntegrator::create(params, k).value();
  DepthImage depth(k.width, k.height, 1.5f);
  DepthImage holes = depth;
  // A block of NaN / inf / negative / too-far pixels: counted, and the voxels in front of them
  // stay as they are without those pixels (no free space carved from NaN).
  size_t bad = 0, far = 0;
  for (int v = 40; v < 80; ++v) {
    for (int u = 40; u < 80; ++u) {
      const int kind = (u + v) % 4;
      depth.at(u, v) = kind == 0 ? std::nanf("") : kind == 1 ? INFINITY : kind == 2 ? -1.0f : 9.0f;
      holes.at(u, v) = 0.0f;
      (kind == 3 ? far : bad)++;
    }
  }
  auto stats = integrator.integrate(depth, Transform::Identity(), &with_bad);
  ASSERT_TRUE(stats.ok());
  EXPECT_EQ(stats->invalid_depth, bad);
  EXPECT_EQ(stats->out_of_range, far);
  ASSERT_TRUE(integrator.integrate(holes, Transform::Identity(), &clean).ok());
  ASSERT_EQ(with_bad.numBlocks(), clean.numBlocks());
  for (const auto& [index, block] : clean.blocks()) {
    const TsdfBlock* other = with_bad.block(index);
    ASSERT_NE(other, nullptr);
    for (size_t i = 0; i < block->voxels().size(); ++i) {
      ASSERT_EQ(block->voxels()[i].distance, other->voxels()[i].distance);
      ASSERT_EQ(block->voxels()[i].weight, other->voxels()[i].weight);
    }
  }
}

TEST(TsdfIntegrator, TwoThreadsGiveTheSameMapAsOne) {
  const Intrinsics k = Intrinsics::vga();
  const TsdfParams params = params2cm();
  const TriangleMesh box = sim::makeBox({0.6f, 0.4f, 0.5f});
  Transform T_world_box = Transform::Identity();
  T_world_box.translation() = Eigen::Vector3d(0, 0, 1.8);
  T_world_box.linear() = Eigen::AngleAxisd(0.6, Eigen::Vector3d(1, 1, 0).normalized()).toRotationMatrix();
  sim::RenderOutput out;
  sim::Renderer(k).render({sim::RenderInstance{&box, T_world_box, 1}}, Transform::Identity(), &out);
  TsdfLayer one = TsdfLayer::create(params.voxel_size_m, 8).value();
  TsdfLayer two = TsdfLayer::create(params.voxel_size_m, 8).value();
  ASSERT_TRUE(TsdfIntegrator::create(params, k, 1)->integrate(out.depth, Transform::Identity(), &one).ok());
  ASSERT_TRUE(TsdfIntegrator::create(params, k, 2)->integrate(out.depth, Transform::Identity(), &two).ok());
  ASSERT_EQ(one.numBlocks(), two.numBlocks());
  for (const auto& [index, block] : one.blocks()) {
    const TsdfBlock* other = two.block(index);
    ASSERT_NE(other, nullptr);
    for (size_t i = 0; i < block->voxels().size(); ++i) {
      ASSERT_EQ(block->voxels()[i].distance, other->voxels()[i].distance);
      ASSERT_EQ(block->voxels()[i].weight, other->voxels()[i].weight);
    }
  }
}

}  // namespace
}  // namespace objdb::tsdf
