#include "client/db_replay.h"

#include <algorithm>
#include <set>

#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "core/database/object_database.h"

namespace objdb::cli {
namespace {

using SegmentSet = std::vector<std::string>;  // "session/label", sorted

SegmentSet segmentsOf(const std::vector<std::pair<std::string, uint32_t>>& keys) {
  SegmentSet out;
  for (const auto& [session, label] : keys) out.push_back(absl::StrFormat("%s/%d", session, label));
  std::sort(out.begin(), out.end());
  return out;
}

}  // namespace

StatusOr<ReplayReport> replayInCreationOrder(const storage::Store& store, const Params& params) {
  ReplayReport report;
  database::InMemoryModelStore memory;
  OBJDB_ASSIGN_OR_RETURN(const std::vector<storage::SessionInfo> sessions, store.sessions());
  for (const auto& s : sessions) {
    OBJDB_ASSIGN_OR_RETURN(auto scene, store.scene(s.name));
    OBJDB_ASSIGN_OR_RETURN(auto labels, store.sceneLabels(s.name));
    if (scene != nullptr) OBJDB_RETURN_IF_ERROR(memory.putScene(s.name, scene, labels));
  }
  OBJDB_ASSIGN_OR_RETURN(std::unique_ptr<database::ObjectDatabase> db,
                         database::ObjectDatabase::create(params, &memory));
  OBJDB_ASSIGN_OR_RETURN(const std::vector<database::SegmentKey> keys, store.rawSegmentKeys());
  for (const database::SegmentKey& key : keys) {
    OBJDB_ASSIGN_OR_RETURN(const auto record, store.rawSegment(key));
    gsm::RawSegment segment{key.label, record->T_world_segment, record->grid->clone(),
                            record->voxels, record->extraction_frame, record->extraction_frame,
                            record->observation_depth_m, record->parts, record->voxel_parts};
    const auto inserted = db->insertSegment(key.session, segment);
    if (!inserted.ok()) {
      return annotate(inserted.status(),
                      absl::StrFormat("replaying segment %s/%d", key.session, key.label));
    }
    ++report.segments;
  }

  std::set<SegmentSet> stored, replayed;
  storage::ModelQuery all;
  all.limit = size_t(1) << 40;
  OBJDB_ASSIGN_OR_RETURN(const std::vector<storage::ModelSummary> summaries,
                         store.modelSummaries(all));
  for (const auto& m : summaries) {
    std::vector<std::pair<std::string, uint32_t>> held;
    for (const auto& o : m.observations) held.emplace_back(o.session, o.label);
    stored.insert(segmentsOf(held));
  }
  OBJDB_ASSIGN_OR_RETURN(const std::vector<int64_t> ids, memory.modelIds());
  for (const int64_t id : ids) {
    OBJDB_ASSIGN_OR_RETURN(const auto model, memory.model(id));
    std::vector<std::pair<std::string, uint32_t>> held;
    for (const auto& o : model->observations) held.emplace_back(o.session, o.label);
    replayed.insert(segmentsOf(held));
  }
  report.models_stored = summaries.size();
  report.models_replayed = ids.size();
  for (const auto& s : stored) {
    if (!replayed.count(s)) report.only_stored.push_back(absl::StrJoin(s, ", "));
  }
  for (const auto& s : replayed) {
    if (!stored.count(s)) report.only_replayed.push_back(absl::StrJoin(s, ", "));
  }
  OBJDB_ASSIGN_OR_RETURN(const auto merges_stored, store.mergeRecords());
  OBJDB_ASSIGN_OR_RETURN(const auto merges_replayed, memory.mergeRecords());
  report.merges_stored = merges_stored.size();
  report.merges_replayed = merges_replayed.size();
  return report;
}

}  // namespace objdb::cli
