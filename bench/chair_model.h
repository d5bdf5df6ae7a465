// A chair-sized object model for the benchmarks (storage_bench, features_bench): the TSDF of a
// chair at 1 cm (seat, back, four legs; observed band ±3 voxels, weights varying as a sensor
// leaves them), and the model core/model builds from it (surface cloud of ~10.7k points,
// ISS ∪ Harris3D keypoints, FPFH). `variant` changes the sizes by a few centimetres.
#pragma once

#include "core/common/status.h"
#include "core/model/object_model.h"

namespace objdb::bench {

StatusOr<model::ObjectModel> chairModel(int variant, int threads = 1);

}  // namespace objdb::bench
