#include "bench/chair_model.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdint>
#include <utility>

#include "core/model/features.h"

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

std::vector<tsdf::VoxelIndex> addChair(tsdf::TsdfLayer* grid, int variant,
                                       const Eigen::Isometry3f& T_grid_chair) {
  const float voxel = grid->voxelSize(), trunc = 3.0f * voxel;
  const float width = 0.44f + 0.02f * float(variant), depth = 0.42f + 0.015f * float(variant);
  const float seat = 0.45f, back = 0.40f + 0.02f * float(variant);
  std::vector<tsdf::VoxelIndex> voxels;
  // The chair's box (with a 5 cm margin) in the grid's frame: the corners' bounds.
  const Eigen::Vector3f box_lo(-width / 2 - 0.05f, -depth / 2 - 0.05f, -0.05f);
  const Eigen::Vector3f box_hi(width / 2 + 0.05f, depth / 2 + 0.05f, seat + back + 0.05f);
  Eigen::Vector3f frame_lo = Eigen::Vector3f::Constant(INFINITY), frame_hi = -frame_lo;
  for (int corner = 0; corner < 8; ++corner) {
    const Eigen::Vector3f c((corner & 1) ? box_hi.x() : box_lo.x(),
                            (corner & 2) ? box_hi.y() : box_lo.y(),
                            (corner & 4) ? box_hi.z() : box_lo.z());
    frame_lo = frame_lo.cwiseMin(T_grid_chair * c);
    frame_hi = frame_hi.cwiseMax(T_grid_chair * c);
  }
  const Eigen::Vector3i lo = (frame_lo / voxel).array().floor().cast<int>();
  const Eigen::Vector3i hi = (frame_hi / voxel).array().ceil().cast<int>();
  const Eigen::Isometry3f T_chair_grid = T_grid_chair.inverse();
  for (int x = lo.x(); x <= hi.x(); ++x) {
    for (int y = lo.y(); y <= hi.y(); ++y) {
      for (int z = lo.z(); z <= hi.z(); ++z) {
        const tsdf::VoxelIndex v(x, y, z);
        const Eigen::Vector3f c = grid->voxelCenter(v);
        const float d = chairSdf(T_chair_grid * c, width, depth, seat, back);
        if (std::abs(d) > trunc) continue;
        tsdf::TsdfBlock& block = grid->allocateBlock(grid->blockOfVoxel(v));
        tsdf::TsdfVoxel& out = block.voxel(grid->linearInBlock(v));
        out.distance = d;
        // Weights as a sensor leaves them: higher where seen more often, varying smoothly.
        out.weight = 5.0f + 20.0f * (0.5f + 0.5f * std::sin(c.x() * 13.0f + c.z() * 7.0f));
        out.color = {uint8_t(120 + x % 8), uint8_t(80 + y % 8), uint8_t(60 + z % 8)};
        if (std::abs(d) < voxel) voxels.push_back(v);
      }
    }
  }
  return voxels;
}

ChairGrid chairGrid(int variant, const Eigen::Isometry3f& T_frame_chair) {
  tsdf::TsdfLayer grid = tsdf::TsdfLayer::create(0.01f, 8).value();
  std::vector<tsdf::VoxelIndex> voxels = addChair(&grid, variant, T_frame_chair);
  return ChairGrid{std::move(grid), std::move(voxels)};
}

StatusOr<model::ObjectModel> chairModel(int variant, int threads,
                                        const Eigen::Isometry3f& T_frame_chair) {
  ChairGrid chair = chairGrid(variant, T_frame_chair);
  model::ModelBuildParams params;
  params.mesh_min_weight = 1.0f;
  params.threads = threads;
  return model::buildModel(std::move(chair.grid), chair.surface_voxels, params);
}

StatusOr<model::ObjectModel> describedChairModel(int variant, size_t num_keypoints) {
  OBJDB_ASSIGN_OR_RETURN(model::ObjectModel built, chairModel(variant));
  // The database's own keypoints (ISS ∪ Harris3D ∪ uniform) first, evenly thinned to
  // num_keypoints when there are more, so that the descriptors are distributed as an inserted
  // segment's are (the global descriptor compares distributions); points spread over the cloud
  // make up the rest when there are fewer.
  std::vector<uint32_t> keypoints;
  const std::vector<uint32_t>& own = built.keypoint_indices;
  for (size_t k = 0; k < num_keypoints && k < own.size(); ++k) {
    keypoints.push_back(own[k * own.size() / std::min(num_keypoints, own.size())]);
  }
  const size_t n = built.cloud.points.size();
  const size_t extra = num_keypoints - keypoints.size();
  for (size_t k = 0; k < extra && k < n; ++k) keypoints.push_back(uint32_t(k * n / extra));
  std::sort(keypoints.begin(), keypoints.end());
  keypoints.erase(std::unique(keypoints.begin(), keypoints.end()), keypoints.end());

  built.descriptors = model::computeFpfh(built.cloud, &keypoints, DescriptorParams{});
  built.keypoint_indices = std::move(keypoints);
  return built;
}

}  // namespace objdb::bench
