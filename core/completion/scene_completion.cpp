#include "core/completion/scene_completion.h"

#include <algorithm>

#include "absl/container/flat_hash_set.h"
#include "absl/strings/str_format.h"
#include "core/common/grid_key.h"

namespace objdb::completion {
namespace {

// The model's surface voxels and every voxel within `margin` of them (a cube neighbourhood),
// in a deterministic order.
std::vector<tsdf::VoxelIndex> objectRegion(const model::ObjectModel& model, int margin) {
  std::vector<tsdf::VoxelIndex> region;
  absl::flat_hash_set<uint64_t> seen;
  for (const tsdf::VoxelIndex& v : model.surface_voxels) {
    for (int z = -margin; z <= margin; ++z) {
      for (int y = -margin; y <= margin; ++y) {
        for (int x = -margin; x <= margin; ++x) {
          const tsdf::VoxelIndex n = v + tsdf::VoxelIndex(x, y, z);
          if (seen.insert(packGridKey(n)).second) region.push_back(n);
        }
      }
    }
  }
  return region;
}

}  // namespace

StatusOr<tsdf::TsdfLayer> completeScene(const database::ModelStore& store,
                                        const std::string& session, const MergingParams& merging,
                                        const TsdfParams& tsdf, CompletionReport* report,
                                        const std::function<bool()>& cancelled) {
  OBJDB_RETURN_IF_ERROR(merging.validate());
  OBJDB_RETURN_IF_ERROR(tsdf.validate());
  OBJDB_ASSIGN_OR_RETURN(const auto scene, store.scene(session));
  if (scene == nullptr) {
    return absl::NotFoundError(absl::StrFormat("completion: no scene map for session %s", session));
  }
  // Checks run against the scene as measured, fills go into the copy: one object's fill never
  // decides another's verification.
  tsdf::TsdfLayer completed = scene->clone();
  CompletionReport local;
  CompletionReport& out = report ? *report : local;
  out = {};
  // Which models to load: built from >= 2 segments, one of them of this session (the prefilter's
  // entries say so without decoding grids).
  OBJDB_ASSIGN_OR_RETURN(const database::MatchEntries entries, store.matchEntries(false));
  // A model that cannot be read might be one of this session's: say so rather than leave it out.
  if (!entries.skipped.empty()) return entries.skipped.front();
  // A model with a merge beyond the paper's e*_TSDF (loosened with a session's measured depth
  // noise, MergingParams::noise_sigmas) is one object for the database, but its grid is as
  // blurred as that session's poses: it is placed and checked, and fills nothing.
  OBJDB_ASSIGN_OR_RETURN(const std::vector<database::MergeRecord> merges, store.mergeRecords());
  absl::flat_hash_set<int64_t> blurred;
  for (const database::MergeRecord& m : merges) {
    if (m.tsdf_rmse_m > double(merging.tsdf_max_rmse_m)) blurred.insert(m.target);
  }
  std::vector<int64_t> ids;
  for (const auto& e : entries.entries) {
    const bool here = std::any_of(e.segments.begin(), e.segments.end(),
                                  [&](const database::SegmentKey& k) { return k.session == session; });
    if (e.segments.size() >= 2 && here) ids.push_back(e.id);
  }
  for (size_t done = 0; done < ids.size(); ++done) {
    if (cancelled && cancelled()) {
      return absl::CancelledError(absl::StrFormat(
          "completion of session %s cancelled after %d of %d models", session, done, ids.size()));
    }
    const int64_t id = ids[done];
    OBJDB_ASSIGN_OR_RETURN(auto model, store.model(id));
    if (model->observations.size() < 2) continue;
    std::vector<tsdf::VoxelIndex> region;  // built on the first verified placement
    for (const auto& o : model->observations) {
      if (o.session != session) continue;
      Placement p;
      p.model_id = id;
      p.label = o.label;
      p.T_world_object = o.T_world_object;
      p.model_segments = model->observations.size();
      p.verdict = matching::judge(
          matching::compareGrids(model->grid, *scene, o.T_world_object.inverse()), merging,
          model->grid.voxelSize());
      p.verified = p.verdict.accepted;
      p.blurred = blurred.contains(id);
      if (p.verified && !p.blurred) {
        if (region.empty()) region = objectRegion(*model, merging.completion_margin_voxels);
        matching::MergeOptions fill;
        fill.mode = matching::MergeMode::kFillUnobserved;
        fill.observed_min_weight = tsdf.mesh_min_weight;
        fill.source_region = &region;
        p.filled_voxels = matching::mergeGrids(&completed, model->grid, o.T_world_object,
                                               tsdf.max_weight, fill, &p.filled_surface_voxels);
      }
      out.filled_voxels += p.filled_voxels;
      out.placements.push_back(p);
    }
  }
  return completed;
}

}  // namespace objdb::completion
