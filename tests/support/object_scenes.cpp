#include "tests/support/object_scenes.h"

#include <cmath>

namespace objdb::testing {
namespace {

const Eigen::Vector3f kLo(-2, -2, -0.2f), kHi(2, 2, 1.2f);

// Leaves observed only the voxels whose position `keep` accepts.
void forget(tsdf::TsdfLayer* layer, const std::function<bool(const Eigen::Vector3f&)>& keep) {
  const int vps = layer->voxelsPerSide();
  for (const auto& [index, block] : layer->blocks()) {
    auto& voxels = block->voxels();
    for (size_t i = 0; i < voxels.size(); ++i) {
      const tsdf::VoxelIndex v = index * vps + Eigen::Vector3i(int(i % size_t(vps)),
                                                               int((i / size_t(vps)) % size_t(vps)),
                                                               int(i / size_t(vps * vps)));
      if (!keep(layer->voxelCenter(v))) voxels[i] = tsdf::TsdfVoxel{};
    }
  }
}

}  // namespace

Sdf boxWithBall() {
  return unionSdf({boxSdf({0, 0, 0.1f}, {0.2f, 0.12f, 0.1f}), sphereSdf({0.03f, 0.08f, 0.22f}, 0.07f),
                   boxSdf({-0.04f, -0.16f, 0.06f}, {0.06f, 0.05f, 0.06f})});
}

Sdf chair() {
  std::vector<Sdf> parts = {boxSdf({0, 0, 0.45f}, {0.22f, 0.22f, 0.03f}),       // seat
                            boxSdf({0, -0.2f, 0.75f}, {0.22f, 0.03f, 0.28f})};  // back
  for (int i = 0; i < 4; ++i) {
    parts.push_back(boxSdf({(i & 1) ? 0.18f : -0.18f, (i & 2) ? 0.18f : -0.18f, 0.21f},
                           {0.03f, 0.03f, 0.21f}));
  }
  return unionSdf(parts);
}

Sdf extinguisher() {
  return unionSdf({cylinderSdf({0, 0, 0.3f}, 0.09f, 0.3f), sphereSdf({0, 0, 0.6f}, 0.09f),
                   boxSdf({0.1f, 0, 0.62f}, {0.06f, 0.02f, 0.02f})});
}

Transform poseXyYaw(double x, double y, double yaw) {
  return Transform(Eigen::Translation3d(x, y, 0)) *
         Transform(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()));
}

tsdf::TsdfLayer sceneGrid(const std::vector<PlacedShape>& shapes, const std::vector<View>& views) {
  std::vector<Sdf> placed;
  for (const auto& s : shapes) placed.push_back(transformedSdf(s.shape, s.T_world_object.cast<float>()));
  tsdf::TsdfLayer layer = sdfGrid(unionSdf(placed), kLo, kHi, kSceneVoxel, kSceneBand).layer;
  if (!views.empty()) {
    forget(&layer, [&](const Eigen::Vector3f& p) {
      // Unobserved: within a shape's band but outside its view.
      for (size_t k = 0; k < shapes.size() && k < views.size(); ++k) {
        const Eigen::Vector3f q = shapes[k].T_world_object.inverse().cast<float>() * p;
        if (std::abs(shapes[k].shape(q)) <= kSceneBand && !views[k].contains(q)) return false;
      }
      return true;
    });
  }
  return layer;
}

gsm::RawSegment rawSegment(uint32_t label, const PlacedShape& shape, const View& view) {
  const Eigen::Isometry3f T = shape.T_world_object.cast<float>();
  const Eigen::Isometry3f T_object_world = T.inverse();
  auto grid = sdfGrid(transformedSdf(shape.shape, T), kLo, kHi, kSceneVoxel, kSceneBand);
  forget(&grid.layer, [&](const Eigen::Vector3f& p) { return view.contains(T_object_world * p); });
  gsm::RawSegment raw{label, Transform::Identity(), std::move(grid.layer), {}, 0, 0};
  for (const auto& v : grid.surface_voxels) {
    const Eigen::Vector3f p = T_object_world * raw.grid.voxelCenter(v);
    if (view.contains(p) && p.z() > 0.01f) raw.label_voxels.push_back(v);
  }
  return raw;
}

}  // namespace objdb::testing
