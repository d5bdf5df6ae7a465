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

}  // namespace objdb::testing
