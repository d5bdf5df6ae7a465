#include "bench/chair_model.h"

#include <algorithm>
#include <cmath>
#include <vector>

namespace objdb::bench {
namespace {

float boxSdf(const Eigen::Vector3f& p, const Eigen::Vector3f& centre, const Eigen::Vector3f& half) {
  const Eigen::Vector3f q = (p - centre).cwiseAbs() - half;
  return q.cwiseMax(0.0f).norm() + std::min(q.maxCoeff(), 0.0f);
}

// A chair of the given size: seat, back and four legs (metres).
float chairSdf(const Eigen::Vector3f& p, float width, float depth, float seat_height,
               float back_height) {
  const float leg = 0.02f;
  float d = boxSdf(p, {0, 0, seat_height}, {width / 2, depth / 2, 0.02f});
  d = std::min(d, boxSdf(p, {0, depth / 2 - 0.015f, seat_height + back_height / 2},
                         {width / 2, 0.015f, back_height / 2}));
  for (const float sx : {-1.0f, 1.0f}) {
    for (const float sy : {-1.0f, 1.0f}) {
      d = std::min(d, boxSdf(p, {sx * (width / 2 - leg), sy * (depth / 2 - leg), seat_height / 2},
                             {leg, leg, seat_height / 2}));
    }
  }
  return d;
}

}  // namespace

StatusOr<model::ObjectModel> chairModel(int variant, int threads,
                                        const Eigen::Isometry3f& T_frame_chair) {
  const float voxel = 0.01f, trunc = 0.03f;
  const float width = 0.44f + 0.02f * float(variant), depth = 0.42f + 0.015f * float(variant);
  const float seat = 0.45f, back = 0.40f + 0.02f * float(variant);
  tsdf::TsdfLayer grid = tsdf::TsdfLayer::create(voxel, 8).value();
  std::vector<tsdf::VoxelIndex> voxels;
  // The chair's box (with a 5 cm margin) in the model frame: the corners' bounds.
  const Eigen::Vector3f box_lo(-width / 2 - 0.05f, -depth / 2 - 0.05f, -0.05f);
  const Eigen::Vector3f box_hi(width / 2 + 0.05f, depth / 2 + 0.05f, seat + back + 0.05f);
  Eigen::Vector3f frame_lo = Eigen::Vector3f::Constant(INFINITY), frame_hi = -frame_lo;
  for (int corner = 0; corner < 8; ++corner) {
    const Eigen::Vector3f c((corner & 1) ? box_hi.x() : box_lo.x(),
                            (corner & 2) ? box_hi.y() : box_lo.y(),
                            (corner & 4) ? box_hi.z() : box_lo.z());
    frame_lo = frame_lo.cwiseMin(T_frame_chair * c);
    frame_hi = frame_hi.cwiseMax(T_frame_chair * c);
  }
  const Eigen::Vector3i lo = (frame_lo / voxel).array().floor().cast<int>();
  const Eigen::Vector3i hi = (frame_hi / voxel).array().ceil().cast<int>();
  const Eigen::Isometry3f T_chair_frame = T_frame_chair.inverse();
  for (int x = lo.x(); x <= hi.x(); ++x) {
    for (int y = lo.y(); y <= hi.y(); ++y) {
      for (int z = lo.z(); z <= hi.z(); ++z) {
        const tsdf::VoxelIndex v(x, y, z);
        const Eigen::Vector3f c = grid.voxelCenter(v);
        const float d = chairSdf(T_chair_frame * c, width, depth, seat, back);
        if (std::abs(d) > trunc) continue;
        tsdf::TsdfBlock& block = grid.allocateBlock(grid.blockOfVoxel(v));
        tsdf::TsdfVoxel& out = block.voxel(grid.linearInBlock(v));
        out.distance = d;
        // Weights as a sensor leaves them: higher where seen more often, varying smoothly.
        out.weight = 5.0f + 20.0f * (0.5f + 0.5f * std::sin(c.x() * 13.0f + c.z() * 7.0f));
        out.color = {uint8_t(120 + x % 8), uint8_t(80 + y % 8), uint8_t(60 + z % 8)};
        if (std::abs(d) < voxel) voxels.push_back(v);
      }
    }
  }
  model::ModelBuildParams params;
  params.mesh_min_weight = 1.0f;
  params.threads = threads;
  return model::buildModel(std::move(grid), voxels, params);
}

}  // namespace objdb::bench
