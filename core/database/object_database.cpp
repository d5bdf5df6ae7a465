#include "core/database/object_database.h"

#include "core/database/merge_source.h"
#include "core/database/parallel_for.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <set>

#include "absl/strings/str_format.h"
#include "core/common/logging.h"
#include "core/common/plane_spans.h"
#include "core/model/global_descriptor.h"
#include "core/model/structure.h"

namespace objdb::database {
namespace {

using Clock = std::chrono::steady_clock;

// FNV-1a over the descriptors' bytes (~66 KB for 500 keypoints: tens of microseconds).
uint64_t descriptorFingerprint(const std::vector<model::Fpfh>& descriptors) {
  uint64_t h = 14695981039346656037ull;
  const auto* bytes = reinterpret_cast<const unsigned char*>(descriptors.data());
  const size_t n = descriptors.size() * sizeof(model::Fpfh);
  for (size_t i = 0; i < n; ++i) h = (h ^ bytes[i]) * 1099511628211ull;
  return h ^ n;
}
double msSince(Clock::time_point t) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

}  // namespace

StatusOr<std::unique_ptr<ObjectDatabase>> ObjectDatabase::create(const Params& params,
                                                                 ModelStore* store) {
  OBJDB_RETURN_IF_ERROR(params.validate());
  if (store == nullptr) return absl::InvalidArgumentError("object database: no store given");
  std::unique_ptr<ObjectDatabase> db(new ObjectDatabase(params, store));
  // Which model holds which segment, from the store (a reopened database carries on); on a
  // shared store under the writer lock, so that the change sequence matches the entries.
  OBJDB_ASSIGN_OR_RETURN(const std::unique_ptr<WriterLock> writer, store->lockWriter());
  if (writer != nullptr) {
    OBJDB_ASSIGN_OR_RETURN(db->applied_seq_, store->modelChangeSeq());
  }
  // With a short list the local descriptors stay in the store (read per insert for the list).
  const bool listed = params.database.shortlist > 0;
  OBJDB_ASSIGN_OR_RETURN(MatchEntries entries, store->matchEntries(/*descriptors=*/!listed));
  std::vector<MatchEntry*> matchable;
  for (auto& e : entries.entries) {
    for (const auto& key : e.segments) db->segment_model_[key] = e.id;
    if (e.matchable(params.model)) matchable.push_back(&e);
  }
  OBJDB_RETURN_IF_ERROR(db->loadGlobalIndex(matchable));
  if (!listed) {
    std::vector<std::pair<int64_t, std::vector<model::Fpfh>*>> descriptors;
    for (MatchEntry* e : matchable) descriptors.emplace_back(e->id, &e->descriptors);
    db->prefilter_.load(descriptors, params.database.threads);
  }
  for (const auto& skipped : entries.skipped) {
    logger("database")->error("object database: a stored model is unreadable and left out: {}",
                              std::string(skipped.message()));
  }
  return db;
}

ObjectDatabase::ObjectDatabase(const Params& params, ModelStore* store)
    : params_(params), store_(store), prefilter_(params.database.prefilter_epsilon) {}

model::ModelBuildParams ObjectDatabase::buildParams(float observation_depth_m) const {
  model::ModelBuildParams p;
  p.observation_depth_m = observation_depth_m;
  p.model = params_.model;
  p.keypoints = params_.keypoints;
  p.descriptors = params_.descriptors;
  p.mesh_min_weight = params_.tsdf.mesh_min_weight;
  p.threads = params_.database.threads;
  return p;
}

StatusOr<std::shared_ptr<const tsdf::TsdfLayer>> ObjectDatabase::sceneOf(
    const std::string& session, const LiveScenes& live) const {
  if (live) {
    if (std::shared_ptr<const tsdf::TsdfLayer> scene = live(session)) return scene;
  }
  return store_->scene(session);
}

StatusOr<float> ObjectDatabase::growInScene(const std::string& session,
                                            const model::ObjectModel& incoming,
                                            const LiveScenes& live) {
  const ModelParams& p = params_.model;
  if (p.structure_max_planes <= 0 || incoming.plane_inlier_ratio < p.structure_min_share ||
      incoming.observations.empty()) {
    return 0.0f;
  }
  OBJDB_ASSIGN_OR_RETURN(const std::shared_ptr<const tsdf::TsdfLayer> scene,
                         sceneOf(session, live));
  if (scene == nullptr) return 0.0f;  // no scene yet: the segment's own planes decided
  const Eigen::Isometry3f T = incoming.observations.front().T_world_object.cast<float>();
  // Every plane holding a good share of the segment: a floor with a strip of wall on it grows
  // over the floor whichever of the two pieces is the bigger.
  std::vector<Eigen::Vector4f> planes = incoming.shared_planes;
  if (planes.empty()) planes.push_back(incoming.plane);
  float span = 0.0f;
  for (const Eigen::Vector4f& plane : planes) {
    const Eigen::Vector3f n = T.linear() * plane.head<3>();
    const Eigen::Vector4f plane_world(n.x(), n.y(), n.z(), plane.w() - n.dot(T.translation()));
    std::vector<Eigen::Vector3f> seeds;
    for (const auto& q : incoming.cloud.points) {
      if (std::abs(plane.head<3>().dot(q) + plane.w()) <= incoming.plane_distance_m) {
        seeds.push_back(T * q);
      }
    }
    const model::GrownPlane grown =
        model::growPlaneInScene(*scene, plane_world, seeds, incoming.plane_distance_m);
    span = std::max(span, grown.span_m[0]);
    if (span >= p.structure_min_extent_m) break;  // structure: no need to grow the rest
  }
  return span;
}

StatusOr<bool> ObjectDatabase::removeContribution(const SegmentKey& key, int64_t model_id) {
  OBJDB_ASSIGN_OR_RETURN(auto held, loadModel(model_id));
  std::vector<model::Observation> remaining;
  for (const auto& o : held->observations) {
    if (keyOf(o) != key) remaining.push_back(o);
  }
  std::optional<MatchEntry> entry;
  const bool emptied = remaining.empty();  // before `remaining` moves into the rebuild
  if (emptied) {
    OBJDB_RETURN_IF_ERROR(store_->removeModel(model_id));
  } else {
    // The model frame stays where it was (the observations are expressed in it), even when
    // the segment that defined it leaves.
    OBJDB_ASSIGN_OR_RETURN(model::ObjectModel rebuilt,
                           buildFromObservations(std::move(remaining), model_id));
    entry = matchEntryOf(rebuilt);
    OBJDB_RETURN_IF_ERROR(store_->replaceModel(std::move(rebuilt), std::nullopt));
  }
  segment_model_.erase(key);
  changed(model_id, std::move(entry));
  return emptied;
}


StatusOr<ObjectDatabase::Withdrawal> ObjectDatabase::withdrawLocked(const std::string& session,
                                                                    gsm::Label label) {
  const SegmentKey key{session, label};
  const auto it = segment_model_.find(key);
  if (it == segment_model_.end()) return Withdrawal{};
  Withdrawal withdrawal;
  withdrawal.model_id = it->second;
  OBJDB_ASSIGN_OR_RETURN(withdrawal.removed, removeContribution(key, withdrawal.model_id));
  return withdrawal;
}

StatusOr<std::shared_ptr<const model::ObjectModel>> ObjectDatabase::loadModel(int64_t id) {
  {
    std::lock_guard lock(mutex_);
    for (auto it = models_.begin(); it != models_.end(); ++it) {
      if ((*it)->id != id) continue;
      models_.splice(models_.begin(), models_, it);
      return models_.front();
    }
  }
  OBJDB_ASSIGN_OR_RETURN(std::shared_ptr<const model::ObjectModel> loaded, store_->model(id));
  std::lock_guard lock(mutex_);
  models_.push_front(loaded);
  if (models_.size() > kCachedModels) models_.pop_back();
  return loaded;
}

void ObjectDatabase::changed(int64_t model_id, std::optional<MatchEntry> entry) {
  std::lock_guard lock(mutex_);
  indices_.erase(model_id);
  models_.remove_if([&](const auto& m) { return m->id == model_id; });
  forgetDescriptors(model_id);
  if (entry && entry->matchable(params_.model)) {
    if (params_.database.shortlist == 0) prefilter_.put(model_id, entry->descriptors);
    global_.put(model_id, entry->global.empty() ? model::globalDescriptor(entry->descriptors)
                                                : entry->global);
  } else {
    prefilter_.erase(model_id);
    global_.erase(model_id);
  }
}

std::shared_ptr<const matching::DescriptorIndex> ObjectDatabase::indexOf(
    const model::ObjectModel& model) {
  // Keyed by id and checked against the descriptors: a match() running beside an insert may hold
  // a version of the model the insert has replaced since; each gets the index of its own.
  const uint64_t fingerprint = descriptorFingerprint(model.descriptors);
  {
    std::lock_guard lock(mutex_);
    const auto it = indices_.find(model.id);
    if (it != indices_.end() && it->second.fingerprint == fingerprint) return it->second.index;
  }
  auto index = std::make_shared<const matching::DescriptorIndex>(model.descriptors);
  std::lock_guard lock(mutex_);
  indices_[model.id] = {fingerprint, index};
  return index;
}

ObjectDatabase::Thresholds ObjectDatabase::thresholdsFor(float depth_m, float noise_scale) const {
  // Only the noise beyond the model's σ(z) loosens: the paper's thresholds hold for a sensor as
  // noisy as the model says (the lounge measures 0.96-1.05; SUN3D's real sweeps 1.9-2.0).
  const double excess =
      std::isfinite(noise_scale) ? std::max(0.0, double(noise_scale) - 1.0) : 0.0;
  const double extra =
      double(params_.merging.noise_sigmas) * excess * params_.model.depthNoise(depth_m);
  return {double(params_.matching.icp_max_rmse_m) + extra,
          double(params_.merging.tsdf_max_rmse_m) + extra, depth_m, noise_scale};
}

CandidateResult ObjectDatabase::evaluate(const model::ObjectModel& incoming,
                                         const model::ObjectModel& candidate,
                                         const Thresholds& thresholds, const LiveScenes& live,
                                         InsertTimings* timings) {
  CandidateResult result;
  result.model_id = candidate.id;
  auto t = Clock::now();
  MatchingParams matching = params_.matching;
  matching.icp_max_rmse_m = float(thresholds.icp_m);
  result.registration =
      matching::registerModels(incoming, candidate, *indexOf(candidate), matching);
  timings->match_register_ms += msSince(t);
  if (!result.registration.accepted) {
    result.stage = "registration";
    result.reason = result.registration.reason;
    return result;
  }
  verifyRegistered(incoming, candidate, thresholds, live, timings, &result);
  return result;
}

void ObjectDatabase::verifyRegistered(const model::ObjectModel& incoming,
                                      const model::ObjectModel& candidate,
                                      const Thresholds& thresholds, const LiveScenes& live,
                                      InsertTimings* timings, CandidateResult* out) {
  CandidateResult& result = *out;
  const Transform& T_j_i = result.registration.T_target_source;
  const Transform T_i_j = T_j_i.inverse();

  // One surface under two GSM labels of one session: the registration puts the candidate's
  // centre where one of its placements of this session already has it.
  const Eigen::Vector3d centre = model::placeCentre(candidate.cloud);
  for (const auto& in : incoming.observations) {
    for (const auto& o : candidate.observations) {
      result.same_place = result.same_place ||
                          model::samePlace(in.session, in.T_world_object * T_i_j, o.session,
                                           o.T_world_object, centre);
    }
  }

  // Model to model: t_i resampled into t_j's lattice, e*_TSDF loosened with the depth noise.
  MergingParams model_check = params_.merging;
  model_check.tsdf_max_rmse_m = float(thresholds.tsdf_m);
  auto t = Clock::now();
  result.model_verdict = matching::judge(
      matching::compareGrids(candidate.grid, incoming.grid, T_j_i), model_check,
      candidate.grid.voxelSize());
  result.colour = matching::compareColours(candidate.grid, incoming.grid, T_j_i);
  timings->model_verify_ms += msSince(t);
  if (!result.model_verdict.accepted) {
    result.stage = "model";
    result.reason = result.model_verdict.reason;
    return;
  }
  const MergingParams& merging = params_.merging;
  if (merging.colour_max_distance > 0.0f &&
      result.colour.pairs >= size_t(merging.colour_min_pairs) &&
      result.colour.median_distance > double(merging.colour_max_distance)) {
    result.stage = "colour";
    result.reason = absl::StrFormat(
        "colours disagree: median chromaticity distance %.3f > %.3f over %d surface voxels",
        result.colour.median_distance, merging.colour_max_distance, result.colour.pairs);
    return;
  }
  // Beyond the paper's thresholds (within the depth noise) only where colour confirms it.
  const double e_icp = result.registration.icp_rmse;
  const double e_tsdf = result.model_verdict.agreement.rmse;
  result.loosened = e_icp > double(params_.matching.icp_max_rmse_m) ||
                    e_tsdf > double(merging.tsdf_max_rmse_m);
  const bool confirmed =
      result.colour.chromatic_pairs >= size_t(merging.colour_min_pairs) &&
      result.colour.chromatic_median_distance <= double(merging.colour_max_distance);
  if (result.loosened && !(merging.colour_max_distance > 0.0f && confirmed)) {
    result.stage = "colour";
    result.reason = absl::StrFormat(
        "e_ICP %.4f m, e_TSDF %.4f m: beyond the paper's %.4f / %.4f m, within the depth noise "
        "(%.1f x sigma at %.2f m), but no colour confirms it (%d chromatic surface voxels, "
        "median distance %.3f)",
        e_icp, e_tsdf, params_.matching.icp_max_rmse_m, merging.tsdf_max_rmse_m,
        thresholds.noise_scale, thresholds.depth_m,
        result.colour.chromatic_pairs, result.colour.chromatic_median_distance);
    return;
  }

  // Model to scene: the merged grid at every pose of both models, against that session's map.
  t = Clock::now();
  tsdf::TsdfLayer merged = candidate.grid.clone();
  matching::mergeGrids(&merged, incoming.grid, T_j_i, params_.tsdf.max_weight);
  std::vector<std::pair<std::string, Transform>> poses;
  for (const auto& o : candidate.observations) poses.emplace_back(o.session, o.T_world_object);
  for (const auto& o : incoming.observations) {
    poses.emplace_back(o.session, o.T_world_object * T_i_j);
  }
  for (const auto& [session, T_world_object] : poses) {
    auto found = sceneOf(session, live);
    if (!found.ok()) {
      result.stage = "scene";
      result.reason = absl::StrFormat("scene of session %s unreadable: %s", session,
                                      found.status().message());
      timings->scene_verify_ms += msSince(t);
      return;
    }
    const std::shared_ptr<const tsdf::TsdfLayer> scene = *std::move(found);
    if (scene == nullptr) {
      ++result.scenes_missing;
      result.stage = "scene";
      result.reason = absl::StrFormat(
          "session %s has no scene map (neither live nor stored) to verify the pose against",
          session);
      timings->scene_verify_ms += msSince(t);
      return;
    }
    const matching::Verdict verdict =
        matching::judge(matching::compareGrids(merged, *scene, T_world_object.inverse()),
                        params_.merging, merged.voxelSize());
    if (!verdict.accepted) {
      result.stage = "scene";
      result.reason = absl::StrFormat("scene of session %s: %s", session, verdict.reason);
      timings->scene_verify_ms += msSince(t);
      return;
    }
    result.scene_rmse_max = std::max(result.scene_rmse_max, verdict.agreement.rmse);
    result.scene_overlap_min = result.scene_checks == 0
                                   ? verdict.agreement.overlap
                                   : std::min(result.scene_overlap_min, verdict.agreement.overlap);
    ++result.scene_checks;
  }
  timings->scene_verify_ms += msSince(t);
  result.accepted = true;
}

namespace {
// `target`'s observations followed by `source`'s, brought into the target's frame by
// T_target_source.
std::vector<model::Observation> joinedObservations(const model::ObjectModel& target,
                                                   const std::vector<model::Observation>& source,
                                                   const Transform& T_target_source) {
  std::vector<model::Observation> out = target.observations;
  const Transform T_source_target = T_target_source.inverse();
  for (const auto& o : source) {
    out.push_back({o.session, o.label, o.T_world_object * T_source_target,
                   T_target_source * o.T_object_segment});
  }
  return out;
}

MergeRecord mergeRecordOf(int64_t target, std::string source, const CandidateResult& r) {
  MergeRecord merge;
  merge.target = target;
  merge.source = std::move(source);
  merge.T_target_source = r.registration.T_target_source;
  merge.icp_rmse_m = r.registration.icp_rmse;
  merge.tsdf_rmse_m = r.model_verdict.agreement.rmse;
  merge.tsdf_overlap = r.model_verdict.agreement.overlap;
  merge.scene_checks = r.scene_checks;
  return merge;
}
}  // namespace

Status ObjectDatabase::absorbCoAccepted(
    std::shared_ptr<const model::ObjectModel> merged, const CandidateResult& best,
    const std::vector<std::shared_ptr<const model::ObjectModel>>& loaded, const LiveScenes& live,
    InsertReport* report) {
  for (size_t c = 0; c < report->results.size(); ++c) {
    const CandidateResult& r = report->results[c];
    if (!r.accepted || r.model_id == merged->id) continue;
    const model::ObjectModel& other = *loaded[c];
    // Both took the segment: T_merged←other = T_merged←segment · T_other←segment⁻¹, refined.
    CandidateResult check;
    check.model_id = other.id;
    auto t = Clock::now();
    check.registration = matching::refineRegistration(
        other, *merged,
        best.registration.T_target_source * r.registration.T_target_source.inverse(),
        params_.matching);
    report->timings.match_register_ms += msSince(t);
    if (!check.registration.accepted) {
      check.stage = "registration";
      check.reason = check.registration.reason;
    } else {
      // A join of two stored models: the paper's thresholds (no segment depth).
      verifyRegistered(other, *merged, thresholdsFor(0.0f, 0.0f), live, &report->timings, &check);
    }
    if (!check.accepted) {
      logger("database")->debug("object {} not merged into object {} (both took the segment): "
                                "rejected at the {} check: {}",
                                other.id, merged->id, check.stage, check.reason);
      report->co_accepted.push_back(std::move(check));
      continue;
    }
    size_t fused = 0;
    OBJDB_ASSIGN_OR_RETURN(
        model::ObjectModel joined,
        extendModel(*merged,
                    joinedObservations(*merged, other.observations,
                                       check.registration.T_target_source),
                    nullptr, &fused));
    report->merge_fused_segments += fused;
    std::vector<SegmentKey> keys;
    for (const auto& o : joined.observations) keys.push_back(keyOf(o));
    MatchEntry entry = matchEntryOf(joined);
    auto next = std::make_shared<const model::ObjectModel>(std::move(joined));
    OBJDB_RETURN_IF_ERROR(store_->absorbModel(
        model::cloneModel(*next),
        mergeRecordOf(merged->id, modelSource(other.id), check), other.id));
    for (const auto& key : keys) segment_model_[key] = merged->id;
    changed(other.id, std::nullopt);
    changed(merged->id, std::move(entry));
    logger("database")->info(
        "object {} merged into object {}: both took one segment (e_ICP {:.4f} m, e_TSDF {:.4f} m, "
        "o_TSDF {}; scene checks {}, worst e_TSDF {:.4f} m)",
        other.id, merged->id, check.registration.icp_rmse, check.model_verdict.agreement.rmse,
        check.model_verdict.agreement.overlap, check.scene_checks, check.scene_rmse_max);
    report->co_accepted.push_back(std::move(check));
    merged = std::move(next);
  }
  return absl::OkStatus();
}

ObjectDatabase::Prepared ObjectDatabase::prepareInsert(const std::string& session,
                                                       const gsm::RawSegment& segment,
                                                       const LiveScenes& live) {
  Prepared prepared;
  InsertReport& report = prepared.report;
  model::ModelBuildParams build = buildParams(segment.observation_depth_m);
  build.structure = segment.structure;  // the room structure's verdict, when the GSM gave one
  auto built = model::buildSegmentModel(segment.grid.clone(), segment.label_voxels, build);
  if (!built.ok()) {
    prepared.error = built.status();
    return prepared;
  }
  if (!built->model) {
    report.unusable = true;
    report.unusable_reason = built->unusable_reason;
    return prepared;
  }
  prepared.incoming = std::move(built->model);
  model::ObjectModel& incoming = *prepared.incoming;
  incoming.observations = {{session, segment.label, segment.T_world_segment, Transform::Identity()}};
  report.timings.cloud_ms = incoming.timings.cloud_ms + incoming.timings.planarity_ms;
  report.timings.keypoints_ms = incoming.timings.keypoints_ms;
  report.timings.descriptors_ms = incoming.timings.descriptors_ms;
  if (segment.structure.has_value()) {
    // The GSM's room structure judged it (core/gsm/room_structure.h, ObjectGroups::structure):
    // one definition of structure for the grouping and for the model's flag. Its planes are
    // found over the whole map with σ(z) bands, which a single segment's planes, or one plane
    // grown from it, are not (docs/structure.md). A label larger than furniture can be is
    // structure there too; the span test below only guards a GSM with other parameters.
    incoming.structure = *segment.structure || principalSpans(incoming.cloud.points)(0) >
                                                   params_.gsm.object_max_extent_m;
  } else if (!incoming.structure) {
    // Not judged by a room structure (the GSM grouped no objects, or a segment from elsewhere):
    // a piece of a bigger face (a partition's top, a strip of wall) is structure too: its plane,
    // grown through the session's scene, is bigger than an object can be. Not for an object
    // the GSM grouped from two or more labels: its grouping never joins a structure label to
    // anything (core/gsm/objects.h), so the room structure has judged such a segment an object,
    // and a chair's seat or back grown through the table it is tucked under is no wall.
    const auto t = Clock::now();
    if (segment.parts.size() < 2) {
      auto grown = growInScene(session, incoming, live);
      if (!grown.ok()) {
        prepared.error = grown.status();
        return prepared;
      }
      report.grown_plane_span_m = *grown;
    }
    incoming.structure = report.grown_plane_span_m >= params_.model.structure_min_extent_m;
    // What is larger than furniture can be is room structure, as the GSM's grouping decides
    // for its labels (core/gsm/objects.h): a bent strip of floor, a counter's whole run.
    incoming.structure = incoming.structure || principalSpans(incoming.cloud.points)(0) >
                                                   params_.gsm.object_max_extent_m;
    report.timings.cloud_ms += msSince(t);  // part of P: the planarity and structure tests
  }
  report.planar = incoming.planar;
  report.structure = incoming.structure;
  report.matchable = incoming.matchable(params_.model);
  logger("database")->debug(
      "segment {}/{}: {} points seen from {:.2f} m (depth noise {:.2f} x sigma), {:.0f} % on one "
      "plane (within {:.1f} cm), grown through the scene to {:.2f} m: {} ({})",
      session, segment.label, incoming.cloud.points.size(), segment.observation_depth_m,
      segment.noise_scale, 100.0 * incoming.plane_inlier_ratio, 100.0 * incoming.plane_distance_m,
      report.grown_plane_span_m,
      incoming.structure ? "structure" : incoming.planar ? "planar" : "object",
      segment.structure.has_value() ? "the room structure's verdict" : "judged here");
  return prepared;
}

StatusOr<InsertReport> ObjectDatabase::insertLocked(const std::string& session,
                                                     const gsm::RawSegment& segment,
                                                     const LiveScenes& live, Prepared prepared) {
  const auto locked = Clock::now();
  InsertReport report = std::move(prepared.report);
  const SegmentKey key{session, segment.label};
  if (const auto it = segment_model_.find(key); it != segment_model_.end()) {
    const auto t = Clock::now();
    const int64_t earlier = it->second;
    OBJDB_ASSIGN_OR_RETURN(const bool emptied, removeContribution(key, earlier));
    if (emptied) report.removed_model = earlier;
    report.replaced_earlier = true;
    report.timings.replace_ms = msSince(t);
  }
  RawSegmentRecord record;
  record.key = key;
  record.T_world_segment = segment.T_world_segment;
  record.grid = std::make_shared<const tsdf::TsdfLayer>(segment.grid.clone());
  record.voxels = segment.label_voxels;
  record.extraction_frame = segment.extraction_frame;
  record.observation_depth_m = segment.observation_depth_m;
  record.parts = segment.parts;
  record.voxel_parts = segment.voxel_parts;
  OBJDB_RETURN_IF_ERROR(store_->putRawSegment(record));
  OBJDB_RETURN_IF_ERROR(prepared.error);
  if (!prepared.incoming) {
    logger("database")->debug("segment {}/{} is unusable, stored without a model: {}", session,
                              segment.label, report.unusable_reason);
    report.timings.writer_hold_ms = msSince(locked);
    return report;
  }
  model::ObjectModel incoming = std::move(*prepared.incoming);

  std::vector<int64_t> candidates;
  std::vector<std::shared_ptr<const model::ObjectModel>> loaded;
  if (report.matchable) {
    auto t = Clock::now();
    OBJDB_ASSIGN_OR_RETURN(std::vector<int64_t> ranked,
                           candidatesFor(incoming, false, &report.shortlist));
    report.timings.prefilter_ms = msSince(t);
    if (measure_prefilter_) {
      OBJDB_ASSIGN_OR_RETURN(report.exhaustive_candidates, candidatesFor(incoming, true));
      report.prefilter_candidates = ranked;
      std::lock_guard lock(mutex_);
      for (const GlobalIndex::Hit& hit :
           global_.nearest(model::globalDescriptor(incoming.descriptors), 0, incoming.id)) {
        report.global_ranking.push_back(hit.id);
      }
    }
    t = Clock::now();
    candidates.reserve(ranked.size());
    for (int64_t id : ranked) {
      auto candidate = loadModel(id);
      if (!candidate.ok()) {
        // A damaged model costs its own matches only; the insert carries on without it.
        ++report.unreadable_candidates;
        logger("database")->warn("segment {}/{}: candidate object {} skipped: {}", session,
                                 segment.label, id, std::string(candidate.status().message()));
        continue;
      }
      candidates.push_back(id);
      loaded.push_back(*std::move(candidate));
    }
    report.timings.load_ms = msSince(t);
  }
  report.candidates = candidates.size();
  report.results.resize(candidates.size());
  std::vector<InsertTimings> per_candidate(candidates.size());
  const Thresholds thresholds = thresholdsFor(segment.observation_depth_m, segment.noise_scale);
  // Waves of `threads` candidates in prefilter order; a wave starts only while fewer than
  // stop_after_accepted have been accepted. A wave may evaluate past the candidate at which one
  // thread would have stopped; the results are then decided in candidate order (below), so the
  // outcome depends neither on thread timing nor on the number of threads.
  const size_t wave = size_t(std::max(1, params_.database.threads));
  const size_t stop = size_t(params_.database.stop_after_accepted);
  size_t accepted = 0;
  for (size_t begin = 0; begin < candidates.size(); begin += wave) {
    const size_t end = std::min(candidates.size(), begin + wave);
    if (stop > 0 && accepted >= stop) {
      for (size_t c = begin; c < candidates.size(); ++c) {
        report.results[c].model_id = candidates[c];
        report.results[c].stage = "skipped";
        report.results[c].reason =
            absl::StrFormat("not evaluated: %d candidates with more votes were accepted", accepted);
      }
      break;
    }
    parallelFor(begin, end, wave, [&](size_t c) {
      report.results[c] = evaluate(incoming, *loaded[c], thresholds, live, &per_candidate[c]);
    });
    for (size_t c = begin; c < end; ++c) accepted += report.results[c].accepted ? 1 : 0;
  }
  if (stop > 0) {
    // What one thread would have done: nothing after the stop-th acceptance counts.
    size_t in_order = 0;
    for (size_t c = 0; c < candidates.size(); ++c) {
      if (in_order >= stop && report.results[c].stage != "skipped") {
        report.results[c] = CandidateResult{};
        report.results[c].model_id = candidates[c];
        report.results[c].stage = "skipped";
        report.results[c].reason = absl::StrFormat(
            "not counted: %d candidates with more votes were accepted (evaluated alongside them)",
            in_order);
      }
      in_order += report.results[c].accepted ? 1 : 0;
    }
  }
  for (const auto& r : report.results) {
    if (r.accepted || r.stage == "skipped") continue;
    logger("database")->debug("segment {}/{}: candidate object {} rejected at the {} check: {}",
                              session, segment.label, r.model_id, r.stage, r.reason);
  }
  for (const auto& t : per_candidate) {
    report.timings.match_register_ms += t.match_register_ms;
    report.timings.model_verify_ms += t.model_verify_ms;
    report.timings.scene_verify_ms += t.scene_verify_ms;
  }

  const auto t_store = Clock::now();
  // The accepted candidate with the lowest e_TSDF (ties: the older model). e_TSDF values within
  // kTiedRmseM tie: copies of one model differ in the last bits only, with the order the hashed
  // grid is summed in, which changes from run to run.
  constexpr double kTiedRmseM = 1e-7;
  const CandidateResult* best = nullptr;
  for (const auto& r : report.results) {
    if (!r.accepted) continue;
    const bool better =
        best == nullptr ||
        r.model_verdict.agreement.rmse < best->model_verdict.agreement.rmse - kTiedRmseM ||
        (std::abs(r.model_verdict.agreement.rmse - best->model_verdict.agreement.rmse) <=
             kTiedRmseM &&
         r.model_id < best->model_id);
    if (better) best = &r;
  }
  if (best == nullptr) {
    MatchEntry entry = matchEntryOf(incoming);
    OBJDB_ASSIGN_OR_RETURN(report.model_id, store_->addModel(std::move(incoming)));
    segment_model_[key] = report.model_id;
    changed(report.model_id, std::move(entry));
  } else {
    const size_t slot = size_t(best - report.results.data());
    const model::ObjectModel& target = *loaded[slot];
    OBJDB_ASSIGN_OR_RETURN(
        model::ObjectModel merged,
        extendModel(target,
                    joinedObservations(target, incoming.observations,
                                       best->registration.T_target_source),
                    &record, &report.merge_fused_segments));
    const MergeRecord merge =
        mergeRecordOf(target.id, segmentSource(session, segment.label), *best);
    std::vector<SegmentKey> keys;
    for (const auto& o : merged.observations) keys.push_back(keyOf(o));
    MatchEntry entry = matchEntryOf(merged);
    size_t co_accepted = 0;
    for (const auto& r : report.results) co_accepted += r.accepted ? 1 : 0;
    std::shared_ptr<const model::ObjectModel> kept;
    if (params_.database.merge_co_accepted && co_accepted > 1) {
      kept = std::make_shared<const model::ObjectModel>(model::cloneModel(merged));
    }
    // What this object knows changes only once the store has the merge: a failed write (I/O
    // error, full disk) leaves the target model as it was, and the insert can be retried. (A
    // re-extracted segment's earlier contribution was removed above, in its own transaction;
    // after a failed write it stays removed until the retry.)
    OBJDB_RETURN_IF_ERROR(store_->replaceModel(std::move(merged), merge));
    for (const auto& key : keys) segment_model_[key] = target.id;
    changed(target.id, std::move(entry));
    report.model_id = target.id;
    report.merged = true;
    logger("database")->info(
        "segment {}/{} merged into object {} (e_ICP {:.4f} m, e_TSDF {:.4f} m, o_TSDF {}; colour "
        "distance {:.3f} over {} voxels{}; scene checks {}, worst e_TSDF {:.4f} m, least o_TSDF "
        "{})",
        session, segment.label, target.id, merge.icp_rmse_m, merge.tsdf_rmse_m, merge.tsdf_overlap,
        best->colour.median_distance, best->colour.pairs,
        best->loosened ? ", thresholds loosened with the depth noise" : "", best->scene_checks,
        best->scene_rmse_max, best->scene_overlap_min);
    if (kept != nullptr) {
      OBJDB_RETURN_IF_ERROR(absorbCoAccepted(std::move(kept), *best, loaded, live, &report));
    }
  }
  if (report.removed_model != 0) {
    // The tombstone of the model the segment's earlier version emptied names where it went. The
    // insert itself is committed: a failure here costs that pointer only.
    if (const Status noted = store_->setSuccessor(report.removed_model, report.model_id);
        !noted.ok()) {
      logger("database")->warn("object {} was removed for segment {}/{}, which is in object {} "
                               "now; recording that failed: {}",
                               report.removed_model, session, segment.label, report.model_id,
                               noted.ToString());
    }
  }
  report.timings.store_ms = msSince(t_store);
  report.timings.writer_hold_ms = msSince(locked);
  return report;
}

}  // namespace objdb::database
