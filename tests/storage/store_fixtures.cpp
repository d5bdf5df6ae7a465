#include "tests/storage/store_fixtures.h"

#include <cstring>
#include <random>

#include "absl/strings/str_format.h"

namespace objdb::testing {
namespace {

Transform randomPose(std::mt19937* rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Eigen::Quaterniond q(u(*rng), u(*rng), u(*rng), u(*rng));
  q.normalize();
  Transform T = Transform::Identity();
  T.linear() = q.toRotationMatrix();
  T.translation() = Eigen::Vector3d(u(*rng), u(*rng), u(*rng)) * 3.0;
  return T;
}

tsdf::TsdfLayer randomGrid(std::mt19937* rng) {
  tsdf::TsdfLayer grid = tsdf::TsdfLayer::create(0.02f, 8).value();
  std::uniform_real_distribution<float> d(-0.06f, 0.06f), w(0.0f, 20.0f);
  std::uniform_int_distribution<int> c(0, 255);
  for (const tsdf::BlockIndex& b : {tsdf::BlockIndex(0, 0, 0), tsdf::BlockIndex(-1, 2, 3)}) {
    for (auto& v : grid.allocateBlock(b).voxels()) {
      v.distance = d(*rng);
      v.weight = (*rng)() % 4 == 0 ? 0.0f : w(*rng);
      v.color = {uint8_t(c(*rng)), uint8_t(c(*rng)), uint8_t(c(*rng))};
    }
  }
  return grid;
}

bool sameBits(const void* a, const void* b, size_t n) { return std::memcmp(a, b, n) == 0; }

}  // namespace

model::ObjectModel makeStoreModel(uint32_t seed, int observations) {
  std::mt19937 rng(seed);
  model::ObjectModel m(randomGrid(&rng));
  std::uniform_real_distribution<float> u(-0.5f, 0.5f);
  const size_t n = size_t(10 * observations);
  for (size_t i = 0; i < n; ++i) {
    m.cloud.points.emplace_back(u(rng), u(rng), u(rng));
    m.cloud.normals.push_back(Eigen::Vector3f(u(rng), u(rng), 1.0f).normalized());
    m.cloud.colors.push_back({uint8_t(rng()), uint8_t(rng()), uint8_t(rng())});
  }
  for (int k = 0; k < 3 * observations; ++k) {
    m.keypoint_indices.push_back(uint32_t(rng() % n));
    model::Fpfh f;
    for (float& x : f) x = u(rng) + 0.5f;
    m.descriptors.push_back(f);
  }
  for (int k = 0; k < 20; ++k) m.surface_voxels.emplace_back(int(rng() % 16), -3, k);
  for (int o = 0; o < observations; ++o) {
    m.observations.push_back({absl::StrFormat("s%d", o), uint32_t(seed % 1000 + o), randomPose(&rng),
                              randomPose(&rng)});
  }
  m.planar = seed % 5 == 0;
  m.plane_inlier_ratio = u(rng) + 0.5f;
  m.timings = {1.5, 2.25, 3.125, 4.0625};
  return m;
}

bool wholeModel(const model::ObjectModel& m) {
  const size_t k = m.observations.size();
  return k > 0 && m.cloud.points.size() == 10 * k && m.cloud.normals.size() == 10 * k &&
         m.keypoint_indices.size() == 3 * k && m.descriptors.size() == 3 * k &&
         m.grid.numBlocks() == 2;
}

database::RawSegmentRecord makeRawSegment(const std::string& session, uint32_t label,
                                          uint32_t seed) {
  std::mt19937 rng(seed);
  database::RawSegmentRecord r;
  r.key = {session, label};
  r.T_world_segment = randomPose(&rng);
  r.grid = std::make_shared<const tsdf::TsdfLayer>(randomGrid(&rng));
  for (int k = 0; k < 50; ++k) r.voxels.emplace_back(int(rng() % 16), int(rng() % 16), -k);
  r.extraction_frame = int64_t(seed) * 7;
  return r;
}

std::string diffLayers(const tsdf::TsdfLayer& a, const tsdf::TsdfLayer& b) {
  if (a.voxelSize() != b.voxelSize() || a.voxelsPerSide() != b.voxelsPerSide()) {
    return "grid geometry differs";
  }
  if (a.numBlocks() != b.numBlocks()) {
    return absl::StrFormat("%d vs %d blocks", a.numBlocks(), b.numBlocks());
  }
  for (const auto& [index, block] : a.blocks()) {
    const tsdf::TsdfBlock* other = b.block(index);
    if (other == nullptr) return "a block is missing";
    for (size_t i = 0; i < block->voxels().size(); ++i) {
      const auto& x = block->voxels()[i];
      const auto& y = other->voxels()[i];
      if (!sameBits(&x.distance, &y.distance, 4) || !sameBits(&x.weight, &y.weight, 4) ||
          !(x.color == y.color)) {
        return absl::StrFormat("voxel %d of block (%d, %d, %d) differs", i, index.x(), index.y(),
                               index.z());
      }
    }
  }
  return "";
}

std::string diffModels(const model::ObjectModel& a, const model::ObjectModel& b) {
  if (a.id != b.id) return absl::StrFormat("id %d vs %d", a.id, b.id);
  if (const std::string d = diffLayers(a.grid, b.grid); !d.empty()) return "grid: " + d;
  if (a.surface_voxels != b.surface_voxels) return "surface voxels differ";
  if (a.cloud.points != b.cloud.points) return "cloud points differ";
  if (a.cloud.normals != b.cloud.normals) return "cloud normals differ";
  if (!(a.cloud.colors == b.cloud.colors)) return "cloud colours differ";
  if (a.keypoint_indices != b.keypoint_indices) return "keypoints differ";
  if (a.descriptors != b.descriptors) return "descriptors differ";
  if (a.planar != b.planar || a.plane_inlier_ratio != b.plane_inlier_ratio) return "planarity differs";
  if (a.structure != b.structure) return "structure differs";
  if (a.timings.cloud_ms != b.timings.cloud_ms || a.timings.descriptors_ms != b.timings.descriptors_ms) {
    return "timings differ";
  }
  if (a.observations.size() != b.observations.size()) return "observation count differs";
  for (size_t k = 0; k < a.observations.size(); ++k) {
    const auto& x = a.observations[k];
    const auto& y = b.observations[k];
    if (x.session != y.session || x.label != y.label) return absl::StrFormat("observation %d differs", k);
    if (!(x.T_world_object.matrix() == y.T_world_object.matrix()) ||
        !(x.T_object_segment.matrix() == y.T_object_segment.matrix())) {
      return absl::StrFormat("pose of observation %d differs", k);
    }
  }
  return "";
}

}  // namespace objdb::testing
