#include "core/tsdf/mesh_extraction.h"

#include <cmath>
#include <map>

#include <gtest/gtest.h>

#include "tests/support/sdf_grid.h"

#include "core/common/params.h"
#include "core/sim/renderer.h"
#include "core/sim/shapes.h"
#include "core/tsdf/tsdf_integrator.h"

namespace objdb::tsdf {
namespace {

// Every voxel within 3 voxels of a sphere, with its exact signed distance.
TsdfLayer analyticSphere(float voxel, float radius, const Eigen::Vector3f& centre) {
  const Eigen::Vector3f reach = Eigen::Vector3f::Constant(radius + 4 * voxel);
  return objdb::testing::sdfGrid(objdb::testing::sphereSdf(centre, radius), centre - reach,
                                 centre + reach, voxel, 3 * voxel)
      .layer;
}

std::map<std::pair<int, int>, int> edgeUse(const TriangleMesh& mesh) {
  std::map<std::pair<int, int>, int> uses;
  for (const auto& t : mesh.triangles) {
    for (int k = 0; k < 3; ++k) {
      const int a = t[k], b = t[(k + 1) % 3];
      ++uses[{std::min(a, b), std::max(a, b)}];
    }
  }
  return uses;
}

TEST(MeshExtraction, SphereHasTheRightAreaAndVolumeAndIsWatertight) {
  const float radius = 0.25f;
  const Eigen::Vector3f centre(0.013f, -0.021f, 0.007f);  // off the grid on purpose
  TsdfLayer layer = analyticSphere(0.01f, radius, centre);
  MeshLayer meshes(1.0f);
  EXPECT_EQ(meshes.update(&layer, true), layer.numBlocks());
  const TriangleMesh mesh = meshes.mesh();
  ASSERT_FALSE(mesh.empty());
  ASSERT_TRUE(mesh.validate().ok());
  const double area = 4 * M_PI * radius * radius, volume = 4.0 / 3.0 * M_PI * radius * radius * radius;
  EXPECT_NEAR(mesh.surfaceArea(), area, 0.02 * area);
  EXPECT_NEAR(mesh.signedVolume(), volume, 0.02 * volume);  // positive: triangles face outward
  for (const auto& [edge, count] : edgeUse(mesh)) ASSERT_EQ(count, 2) << "open or non-manifold edge";
  for (const auto& v : mesh.vertices) ASSERT_NEAR((v - centre).norm(), radius, 0.002f);
  for (size_t i = 0; i < mesh.vertices.size(); ++i) {
    ASSERT_GT(mesh.normals[i].dot((mesh.vertices[i] - centre).normalized()), 0.9f);
  }
}

TEST(MeshExtraction, LightVoxelsAreNotMeshed) {
  TsdfLayer layer = analyticSphere(0.02f, 0.3f, Eigen::Vector3f::Zero());
  MeshLayer heavy(20.0f);  // every voxel has weight 10
  heavy.update(&layer, true);
  EXPECT_TRUE(heavy.mesh().empty());
}

TEST(MeshExtraction, IncrementalUpdatesGiveTheSameMeshAsAFullRemesh) {
  const Intrinsics k = Intrinsics::tango();
  TsdfParams params;
  params.voxel_size_m = 0.02f;
  TsdfLayer layer = TsdfLayer::create(params.voxel_size_m, params.voxels_per_side).value();
  const auto integrator = TsdfIntegrator::create(params, k).value();
  const TriangleMesh box = sim::makeBox({0.5f, 0.4f, 0.3f});
  Transform T_world_box = Transform::Identity();
  T_world_box.translation() = Eigen::Vector3d(0, 0, 1.5);
  const sim::Renderer renderer(k);
  MeshLayer incremental(0.5f);
  sim::RenderOutput out;
  for (int view = 0; view < 5; ++view) {
    const double a = -0.6 + 0.3 * view;
    const Transform T_world_camera =
        lookAt(Eigen::Vector3d(1.4 * std::sin(a), -0.6, 1.5 - 1.4 * std::cos(a)),
               Eigen::Vector3d(0, 0, 1.5))
            .value();
    renderer.render({sim::RenderInstance{&box, T_world_box, 1}}, T_world_camera, &out);
    ASSERT_TRUE(integrator.integrate(out.depth, T_world_camera, &layer).ok());
    const size_t meshed = incremental.update(&layer);
    EXPECT_GT(meshed, 0u);
  }
  EXPECT_EQ(incremental.update(&layer), 0u);  // nothing changed since
  MeshLayer full(0.5f);
  full.update(&layer, true);
  const TriangleMesh a = incremental.mesh(), b = full.mesh();
  ASSERT_FALSE(a.empty());
  ASSERT_EQ(a.vertices.size(), b.vertices.size());
  ASSERT_EQ(a.triangles.size(), b.triangles.size());
  for (size_t i = 0; i < a.vertices.size(); ++i) ASSERT_EQ(a.vertices[i], b.vertices[i]);
  // Vertices lie on the box: within a voxel everywhere (edges and corners are rounded by the
  // grid), within a quarter voxel on average.
  const Transform T_box_world = T_world_box.inverse();
  double sum = 0.0;
  for (const auto& v : a.vertices) {
    const Eigen::Vector3d p = T_box_world * v.cast<double>();
    const double outside = (p.cwiseAbs() - Eigen::Vector3d(0.25, 0.2, 0.15)).maxCoeff();
    ASSERT_LT(std::abs(outside), params.voxel_size_m) << p.transpose();
    sum += std::abs(outside);
  }
  EXPECT_LT(sum / double(a.vertices.size()), 0.25 * params.voxel_size_m);
}

}  // namespace
}  // namespace objdb::tsdf
