// A chair-sized object model for the benchmarks (storage_bench, features_bench, insert_bench): the
// TSDF of a chair at 1 cm (seat, back, four legs; observed band ±3 voxels, weights varying as a
// sensor leaves them), and the model core/model builds from it (surface cloud of ~10.7k points,
// ISS ∪ Harris3D keypoints, FPFH). `variant` changes the sizes by a few centimetres;
// `T_frame_chair` places the chair in the model frame (the grid stays axis-aligned, so a moved
// chair is sampled on another lattice: registration_peers' known transforms).
#pragma once

#include <cstddef>
#include <vector>

#include <Eigen/Geometry>

#include "core/common/status.h"
#include "core/model/object_model.h"
#include "core/tsdf/tsdf_layer.h"

namespace objdb::bench {

// The chair's TSDF at 1 cm and the voxels within one voxel of its surface (those a segment's label
// covers: what the model is built from).
struct ChairGrid {
  tsdf::TsdfLayer grid;
  std::vector<tsdf::VoxelIndex> surface_voxels;
};
ChairGrid chairGrid(int variant,
                    const Eigen::Isometry3f& T_frame_chair = Eigen::Isometry3f::Identity());

// Writes the chair at T_grid_chair into an existing layer (a scene map holding several), at the
// layer's voxel size with a truncation of 3 voxels; returns the voxels near its surface.
std::vector<tsdf::VoxelIndex> addChair(tsdf::TsdfLayer* grid, int variant,
                                       const Eigen::Isometry3f& T_grid_chair);

StatusOr<model::ObjectModel> chairModel(int variant, int threads = 1,
                                        const Eigen::Isometry3f& T_frame_chair =
                                            Eigen::Isometry3f::Identity());

// chairModel with the issue's ~500 described keypoints per model: ISS ∪ Harris3D finds fewer on
// this clean shape, so `num_keypoints` are spread over the cloud and described with the default
// FPFH (storage_bench, insert_bench).
StatusOr<model::ObjectModel> describedChairModel(int variant, size_t num_keypoints = 500);

}  // namespace objdb::bench
