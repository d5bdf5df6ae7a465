#include "core/database/model_store.h"

#include <algorithm>

#include "absl/strings/str_format.h"
#include "core/model/global_descriptor.h"

namespace objdb::database {

namespace {

// As the stores on disk record a merge: the same source merged into the same model again (a
// re-extracted segment) supersedes its earlier record.
void recordMerge(const MergeRecord& merge, std::vector<MergeRecord>* merges) {
  merges->erase(std::remove_if(merges->begin(), merges->end(),
                               [&](const MergeRecord& m) {
                                 return m.target == merge.target && m.source == merge.source;
                               }),
                merges->end());
  merges->push_back(merge);
}

}  // namespace

bool MatchEntry::matchable(const ModelParams& params) const {
  return model::isMatchable(planar || structure, num_points, num_keypoints,
                            descriptors_omitted ? num_keypoints : descriptors.size(), params);
}

MatchEntry matchEntryOf(const model::ObjectModel& model) {
  MatchEntry e;
  e.id = model.id;
  e.planar = model.planar;
  e.structure = model.structure;
  e.num_points = model.cloud.points.size();
  e.num_keypoints = model.keypoint_indices.size();
  e.descriptors = model.descriptors;
  if (!e.descriptors.empty()) e.global = model::globalDescriptor(e.descriptors);
  for (const auto& o : model.observations) e.segments.push_back({o.session, o.label});
  return e;
}

StatusOr<std::vector<std::vector<model::Fpfh>>> ModelStore::descriptorsOf(
    const std::vector<int64_t>& ids) const {
  std::vector<std::vector<model::Fpfh>> out;
  out.reserve(ids.size());
  for (const int64_t id : ids) {
    OBJDB_ASSIGN_OR_RETURN(const std::shared_ptr<const model::ObjectModel> m, model(id));
    out.push_back(m->descriptors);
  }
  return out;
}

Status InMemoryModelStore::putRawSegment(const RawSegmentRecord& segment) {
  if (segment.grid == nullptr) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "raw segment %s/%d has no grid", segment.key.session, segment.key.label));
  }
  std::lock_guard lock(mutex_);
  segments_[segment.key] = std::make_shared<const RawSegmentRecord>(segment);
  return absl::OkStatus();
}

StatusOr<std::shared_ptr<const RawSegmentRecord>> InMemoryModelStore::rawSegment(
    const SegmentKey& key) const {
  std::lock_guard lock(mutex_);
  const auto it = segments_.find(key);
  if (it == segments_.end()) {
    return absl::NotFoundError(
        absl::StrFormat("no raw segment %s/%d", key.session, key.label));
  }
  return it->second;
}

StatusOr<std::vector<float>> ModelStore::observationDepths(
    const std::vector<SegmentKey>& keys) const {
  std::vector<float> depths;
  depths.reserve(keys.size());
  for (const auto& key : keys) {
    OBJDB_ASSIGN_OR_RETURN(const auto segment, rawSegment(key));
    depths.push_back(segment->observation_depth_m);
  }
  return depths;
}

StatusOr<int64_t> InMemoryModelStore::addModel(model::ObjectModel model) {
  std::lock_guard lock(mutex_);
  model.id = next_id_++;
  const int64_t id = model.id;
  models_[id] = std::make_shared<const model::ObjectModel>(std::move(model));
  return id;
}

Status InMemoryModelStore::replaceModel(model::ObjectModel model,
                                        const std::optional<MergeRecord>& merge) {
  std::lock_guard lock(mutex_);
  const auto it = models_.find(model.id);
  if (it == models_.end()) {
    return absl::NotFoundError(absl::StrFormat("no object model %d to replace", model.id));
  }
  it->second = std::make_shared<const model::ObjectModel>(std::move(model));
  if (merge) recordMerge(*merge, &merges_);
  return absl::OkStatus();
}

Status InMemoryModelStore::absorbModel(model::ObjectModel target, const MergeRecord& merge,
                                       int64_t absorbed) {
  std::lock_guard lock(mutex_);
  const auto it = models_.find(target.id);
  if (it == models_.end()) {
    return absl::NotFoundError(absl::StrFormat("no object model %d to merge into", target.id));
  }
  if (absorbed == target.id || models_.count(absorbed) == 0) {
    return absl::NotFoundError(
        absl::StrFormat("no object model %d to merge into model %d", absorbed, target.id));
  }
  it->second = std::make_shared<const model::ObjectModel>(std::move(target));
  models_.erase(absorbed);
  recordMerge(merge, &merges_);
  return absl::OkStatus();
}

Status InMemoryModelStore::removeModel(int64_t id) {
  std::lock_guard lock(mutex_);
  if (models_.erase(id) == 0) {
    return absl::NotFoundError(absl::StrFormat("no object model %d to remove", id));
  }
  return absl::OkStatus();
}

StatusOr<std::shared_ptr<const model::ObjectModel>> InMemoryModelStore::model(int64_t id) const {
  std::lock_guard lock(mutex_);
  const auto it = models_.find(id);
  if (it == models_.end()) return absl::NotFoundError(absl::StrFormat("no object model %d", id));
  return it->second;
}

StatusOr<std::vector<int64_t>> InMemoryModelStore::modelIds() const {
  std::lock_guard lock(mutex_);
  std::vector<int64_t> ids;
  ids.reserve(models_.size());
  for (const auto& [id, model] : models_) ids.push_back(id);
  return ids;
}

StatusOr<MatchEntries> InMemoryModelStore::matchEntries(bool descriptors) const {
  std::lock_guard lock(mutex_);
  MatchEntries out;
  out.entries.reserve(models_.size());
  for (const auto& [id, model] : models_) {
    out.entries.push_back(matchEntryOf(*model));
    if (!descriptors) {
      out.entries.back().descriptors.clear();
      out.entries.back().descriptors_omitted = true;
    }
  }
  return out;
}

StatusOr<std::vector<MergeRecord>> InMemoryModelStore::mergeRecords() const {
  std::lock_guard lock(mutex_);
  return merges_;
}

StatusOr<std::shared_ptr<const tsdf::TsdfLayer>> InMemoryModelStore::scene(
    const std::string& session) const {
  std::lock_guard lock(mutex_);
  const auto it = scenes_.find(session);
  if (it == scenes_.end()) return std::shared_ptr<const tsdf::TsdfLayer>();
  return it->second;
}

Status InMemoryModelStore::putScene(const std::string& session,
                                    std::shared_ptr<const tsdf::TsdfLayer> scene,
                                    std::shared_ptr<const gsm::LabelBlocks> labels) {
  if (scene == nullptr) {
    return absl::InvalidArgumentError(absl::StrFormat("scene of session %s is null", session));
  }
  std::lock_guard lock(mutex_);
  scenes_[session] = std::move(scene);
  scene_labels_[session] = std::move(labels);
  return absl::OkStatus();
}

StatusOr<std::shared_ptr<const gsm::LabelBlocks>> InMemoryModelStore::sceneLabels(
    const std::string& session) const {
  std::lock_guard lock(mutex_);
  const auto it = scene_labels_.find(session);
  if (it == scene_labels_.end()) return std::shared_ptr<const gsm::LabelBlocks>();
  return it->second;
}

}  // namespace objdb::database
