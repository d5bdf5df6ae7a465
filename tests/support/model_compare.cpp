#include "tests/support/model_compare.h"

#include <cstring>

#include "absl/container/flat_hash_set.h"
#include "absl/strings/str_format.h"
#include "core/common/grid_key.h"
#include "core/matching/verification.h"

namespace objdb::testing {

StatusOr<model::ObjectModel> rebuiltFromSegments(const database::ModelStore& store,
                                                 const model::ObjectModel& model,
                                                 const Params& params) {
  if (model.observations.empty()) return absl::InvalidArgumentError("a model without segments");
  std::optional<tsdf::TsdfLayer> grid;
  std::vector<tsdf::VoxelIndex> voxels;
  absl::flat_hash_set<uint64_t> seen;
  double depth_sum = 0.0;
  int depths = 0;
  for (const auto& o : model.observations) {
    OBJDB_ASSIGN_OR_RETURN(const auto segment, store.rawSegment({o.session, o.label}));
    if (segment->observation_depth_m > 0.0f) {
      depth_sum += segment->observation_depth_m;
      ++depths;
    }
    if (!grid) {
      grid.emplace(
          tsdf::TsdfLayer::create(segment->grid->voxelSize(), segment->grid->voxelsPerSide())
              .value());
    }
    matching::mergeGrids(&*grid, *segment->grid, o.T_object_segment, params.tsdf.max_weight);
    const Eigen::Isometry3f T = o.T_object_segment.cast<float>();
    for (const auto& v : segment->voxels) {
      const tsdf::VoxelIndex mapped = grid->voxelIndexOf(T * segment->grid->voxelCenter(v));
      if (seen.insert(packGridKey(mapped)).second) voxels.push_back(mapped);
    }
  }
  model::ModelBuildParams build;
  build.observation_depth_m = depths > 0 ? float(depth_sum / depths) : 0.0f;
  build.model = params.model;
  build.keypoints = params.keypoints;
  build.descriptors = params.descriptors;
  build.mesh_min_weight = params.tsdf.mesh_min_weight;
  build.threads = params.database.threads;
  OBJDB_ASSIGN_OR_RETURN(model::ObjectModel rebuilt,
                         model::buildModel(std::move(*grid), voxels, build));
  rebuilt.id = model.id;
  rebuilt.observations = model.observations;
  return rebuilt;
}

namespace {
bool sameBits(const void* a, const void* b, size_t n) { return std::memcmp(a, b, n) == 0; }
}  // namespace

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

std::string diffModels(const model::ObjectModel& a, const model::ObjectModel& b,
                       bool with_timings) {
  if (a.id != b.id) return absl::StrFormat("id %d vs %d", a.id, b.id);
  if (const std::string d = diffLayers(a.grid, b.grid); !d.empty()) return "grid: " + d;
  if (a.surface_voxels != b.surface_voxels) return "surface voxels differ";
  if (a.cloud.points != b.cloud.points) return "cloud points differ";
  if (a.cloud.normals != b.cloud.normals) return "cloud normals differ";
  if (!(a.cloud.colors == b.cloud.colors)) return "cloud colours differ";
  if (a.keypoint_indices != b.keypoint_indices) return "keypoints differ";
  if (a.descriptors != b.descriptors) return "descriptors differ";
  if (a.planar != b.planar || a.plane_inlier_ratio != b.plane_inlier_ratio)
    return "planarity differs";
  if (a.structure != b.structure) return "structure differs";
  if (with_timings && (a.timings.cloud_ms != b.timings.cloud_ms ||
                       a.timings.descriptors_ms != b.timings.descriptors_ms)) {
    return "timings differ";
  }
  if (a.observations.size() != b.observations.size()) return "observation count differs";
  for (size_t k = 0; k < a.observations.size(); ++k) {
    const auto& x = a.observations[k];
    const auto& y = b.observations[k];
    if (x.session != y.session || x.label != y.label)
      return absl::StrFormat("observation %d differs", k);
    if (!(x.T_world_object.matrix() == y.T_world_object.matrix()) ||
        !(x.T_object_segment.matrix() == y.T_object_segment.matrix())) {
      return absl::StrFormat("pose of observation %d differs", k);
    }
  }
  return "";
}

}  // namespace objdb::testing
