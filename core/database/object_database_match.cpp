// ObjectDatabase::match and matchModel: "what is this?" — a segment's model retrieved and
// verified as an insert's is (object_database.cpp, insertLocked), nothing written.
#include <algorithm>
#include <chrono>

#include "absl/strings/str_format.h"
#include "core/common/logging.h"
#include "core/common/plane_spans.h"
#include "core/database/object_database.h"
#include "core/database/parallel_for.h"

namespace objdb::database {
namespace {

using Clock = std::chrono::steady_clock;
double msSince(Clock::time_point t) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

}  // namespace

StatusOr<MatchReport> ObjectDatabase::match(const gsm::RawSegment& segment,
                                            const LiveScenes& live) {
  MatchReport report;
  model::ModelBuildParams build = buildParams(segment.observation_depth_m);
  build.structure = segment.structure;
  OBJDB_ASSIGN_OR_RETURN(model::SegmentModel built,
                         model::buildSegmentModel(segment.grid.clone(), segment.label_voxels, build));
  if (!built.model) {
    report.unusable = true;
    report.unusable_reason = built.unusable_reason;
    return report;
  }
  model::ObjectModel& incoming = *built.model;
  // No session: the model's own structure test, and what is larger than furniture can be is
  // room structure (as prepareInsert judges a segment no room structure judged; its plane is not
  // grown through a scene, which a query does not have).
  incoming.structure = incoming.structure || principalSpans(incoming.cloud.points)(0) >
                                                 params_.gsm.object_max_extent_m;
  report.timings.cloud_ms = incoming.timings.cloud_ms + incoming.timings.planarity_ms;
  report.timings.keypoints_ms = incoming.timings.keypoints_ms;
  report.timings.descriptors_ms = incoming.timings.descriptors_ms;
  OBJDB_RETURN_IF_ERROR(matchIncoming(
      incoming, thresholdsFor(segment.observation_depth_m, segment.noise_scale), live, &report));
  return report;
}

StatusOr<MatchReport> ObjectDatabase::matchModel(int64_t model_id, const LiveScenes& live) {
  auto loaded = loadModel(model_id);
  if (!loaded.ok()) {
    if (absl::IsNotFound(loaded.status())) {
      return absl::NotFoundError(absl::StrFormat("object %d: no such active object", model_id));
    }
    return loaded.status();
  }
  MatchReport report;
  // The paper's thresholds, as for a join of two stored models (absorbCoAccepted).
  OBJDB_RETURN_IF_ERROR(matchIncoming(**loaded, thresholdsFor(0.0f, 0.0f), live, &report));
  return report;
}

Status ObjectDatabase::matchIncoming(const model::ObjectModel& incoming,
                                     const Thresholds& thresholds, const LiveScenes& live,
                                     MatchReport* report) {
  const auto start = Clock::now();
  report->planar = incoming.planar;
  report->structure = incoming.structure;
  report->matchable = incoming.matchable(params_.model);
  report->points = incoming.cloud.points.size();
  report->keypoints = incoming.descriptors.size();
  if (!report->matchable) return absl::OkStatus();

  auto t = Clock::now();
  OBJDB_ASSIGN_OR_RETURN(const std::vector<int64_t> ranked,
                         candidatesFor(incoming, false, &report->shortlist));
  report->timings.prefilter_ms = msSince(t);
  t = Clock::now();
  std::vector<std::shared_ptr<const model::ObjectModel>> loaded;
  for (const int64_t id : ranked) {
    auto candidate = loadModel(id);
    if (!candidate.ok()) {
      // Removed or merged by an insert since the vote, or damaged: the query goes on without it.
      ++report->unreadable_candidates;
      logger("database")->debug("match: candidate object {} skipped: {}", id,
                                std::string(candidate.status().message()));
      continue;
    }
    loaded.push_back(*std::move(candidate));
  }
  report->timings.load_ms = msSince(t);

  std::vector<InsertTimings> per_candidate(loaded.size());
  report->results.resize(loaded.size());
  parallelFor(0, loaded.size(), size_t(std::max(1, params_.database.threads)), [&](size_t c) {
    report->results[c] = evaluate(incoming, *loaded[c], thresholds, live, &per_candidate[c]);
  });
  for (const auto& s : per_candidate) {
    report->timings.match_register_ms += s.match_register_ms;
    report->timings.model_verify_ms += s.model_verify_ms;
    report->timings.scene_verify_ms += s.scene_verify_ms;
  }
  // Accepted first, by e_TSDF (the candidate a merge would take first); then by how far each got
  // (rejected by the scene, by colour, by the model check, at registration), in vote order.
  auto progress = [](const CandidateResult& r) {
    if (r.accepted) return 4;
    if (r.stage == "scene") return 3;
    if (r.stage == "colour") return 2;
    if (r.stage == "model") return 1;
    return 0;
  };
  std::stable_sort(report->results.begin(), report->results.end(),
                   [&](const CandidateResult& a, const CandidateResult& b) {
                     if (progress(a) != progress(b)) return progress(a) > progress(b);
                     if (!a.accepted) return false;
                     return a.model_verdict.agreement.rmse < b.model_verdict.agreement.rmse;
                   });
  report->timings.total_ms = msSince(start) + report->timings.cloud_ms +
                             report->timings.keypoints_ms + report->timings.descriptors_ms;
  return absl::OkStatus();
}

}  // namespace objdb::database
