// Scene completion (paper §III-C, last step): the merged object models are
// placed at each pose where a session observed them; where a placed model verifies against the
// session's scene TSDF (the same e_TSDF / o_TSDF test as merging), its voxels around its own
// surface voxels (MergingParams::completion_margin_voxels) fill what the scene did not observe:
// voxels it never saw, and voxels seen too little to be meshed (weight below the scene's
// TsdfParams::mesh_min_weight), which are fused with the model by weight. What the scene measured
// is kept: completion adds, it does not overwrite. A model that holds a merge beyond the paper's
// e*_TSDF (accepted within a session's measured depth noise) fills nothing.
#pragma once

#include <functional>

#include <cstdint>
#include <string>
#include <vector>

#include "core/common/params.h"
#include "core/common/status.h"
#include "core/common/transform.h"
#include "core/database/model_store.h"
#include "core/matching/verification.h"
#include "core/tsdf/tsdf_layer.h"

namespace objdb::completion {

// One model at one of its poses in the session.
struct Placement {
  int64_t model_id = 0;
  uint32_t label = 0;  // the GSM label of the segment observed there
  Transform T_world_object = Transform::Identity();
  size_t model_segments = 0;  // how many raw segments built the model
  bool verified = false;
  // The model holds a merge beyond the paper's e*_TSDF (MergingParams::noise_sigmas): it fills
  // nothing, verified or not.
  bool blurred = false;
  matching::Verdict verdict;  // the placed model against the scene
  size_t filled_voxels = 0;   // scene voxels it filled
  size_t filled_surface_voxels = 0;  // of those, within one voxel of its surface
};

struct CompletionReport {
  std::vector<Placement> placements;
  size_t filled_voxels = 0;
};

// The models observed in `session` (every observation of every stored model), completed into a
// copy of the session's scene map. Models built from a single segment add nothing (they are the
// scene's own data) and are skipped. `tsdf`: the session's volume parameters (max_weight caps the
// fused weights, mesh_min_weight says what the scene observed). Errors: the session has no scene
// map in the store.
// `cancelled`, when given, is asked before each model: true ends the work with CANCELLED.
StatusOr<tsdf::TsdfLayer> completeScene(const database::ModelStore& store,
                                        const std::string& session, const MergingParams& merging,
                                        const TsdfParams& tsdf, CompletionReport* report,
                                        const std::function<bool()>& cancelled = {});

}  // namespace objdb::completion
