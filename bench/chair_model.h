// A chair-sized object model for the benchmarks (storage_bench, features_bench): the TSDF of a
// chair at 1 cm (seat, back, four legs; observed band ±3 voxels, weights varying as a sensor
// leaves them), and the model core/model builds from it (surface cloud of ~10.7k points,
// ISS ∪ Harris3D keypoints, FPFH). `variant` changes the sizes by a few centimetres;
// `T_frame_chair` places the chair in the model frame (the grid stays axis-aligned, so a moved
// chair is sampled on another lattice: registration_peers' known transforms).
#pragma once

#include <Eigen/Geometry>

#include "core/common/status.h"
#include "core/model/object_model.h"

namespace objdb::bench {

StatusOr<model::ObjectModel> chairModel(int variant, int threads = 1,
                                        const Eigen::Isometry3f& T_frame_chair =
                                            Eigen::Isometry3f::Identity());

}  // namespace objdb::bench
