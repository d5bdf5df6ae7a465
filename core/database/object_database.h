// The incremental object database (paper §III-C, Algorithm 1): a raw segment becomes an object
// model; a descriptor-vote prefilter picks candidate models; each candidate is registered
// (matching + RANSAC + ICP), verified model to model on the TSDF grids, merged, and the merged
// grid verified against the scene at every observed pose; the accepted candidate with the
// lowest e_TSDF absorbs the new model, otherwise it is stored alone. Candidates are evaluated
// in parallel; the outcome does not depend on the thread count.
#pragma once

#include <cstdint>
#include <functional>
#include <list>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "core/common/params.h"
#include "core/common/status.h"
#include "core/database/model_store.h"
#include "core/database/global_index.h"
#include "core/database/prefilter_index.h"
#include "core/gsm/gsm.h"
#include "core/matching/registration.h"
#include "core/matching/verification.h"
#include "core/model/object_model.h"

namespace objdb::database {

// Why a candidate was not merged, or the numbers that let it merge.
struct CandidateResult {
  int64_t model_id = 0;
  bool accepted = false;
  std::string stage;   // where it stopped: "registration", "model", "colour", "scene",
                       // "skipped" (stop_after_accepted reached before it, in candidate order:
                       // not evaluated, or evaluated by a parallel wave and not counted), or ""
                       // if accepted
  std::string reason;
  matching::Registration registration;
  matching::Verdict model_verdict;
  // The two models' colours where both saw the surface (after the model check passed).
  matching::ColourAgreement colour;
  // Accepted beyond the paper's e*_ICP or e*_TSDF, within the depth noise, with colour confirming
  // (MergingParams::noise_sigmas).
  bool loosened = false;
  // The registration puts the segment onto a placement of its own session (model::samePlace):
  // one surface under two GSM labels. Merged like any match (the model gains its geometry), it
  // adds an observation but no placement.
  bool same_place = false;
  size_t scene_checks = 0;     // poses verified against their scene
  // Poses whose session had no scene map, neither live nor stored: the candidate is rejected at
  // the first (a merge is never accepted on the model-to-model check alone).
  size_t scenes_missing = 0;
  double scene_rmse_max = 0.0;    // worst e_TSDF of the poses checked, metres
  size_t scene_overlap_min = 0;   // smallest o_TSDF of the poses checked
};

// The scene maps of sessions the store does not hold yet (live sessions: the server's GSM
// snapshots). Returns null for a session it does not know; the store is asked then.
using LiveScenes =
    std::function<std::shared_ptr<const tsdf::TsdfLayer>(const std::string& session)>;

// Per insert, ms (paper table II: P, K, D, MR, MV, SV).
struct InsertTimings {
  double cloud_ms = 0, keypoints_ms = 0, descriptors_ms = 0, match_register_ms = 0,
         model_verify_ms = 0, scene_verify_ms = 0, total_ms = 0;
  // Not in table II: removing a re-extracted segment's earlier contribution, the prefilter (index
  // upkeep and votes), loading the candidates, storing the result (a merged model's rebuild
  // included).
  double replace_ms = 0, prefilter_ms = 0, load_ms = 0, store_ms = 0;
  // Several writers on one store: waiting for the writer lock and catching up on the others'
  // changes (0 with one writer), not in total_ms; and the time under the lock (the serial part
  // across writers, in total_ms: everything but the segment's own model, built before the lock).
  double writer_wait_ms = 0, writer_hold_ms = 0;

  InsertTimings& operator+=(const InsertTimings& o);
};

// Every field of InsertTimings with its stage's name (the API's InsertTimingTotals has a field
// <name>_s for each).
inline constexpr std::pair<const char*, double InsertTimings::*> kInsertStages[] = {
    {"cloud", &InsertTimings::cloud_ms},          {"keypoints", &InsertTimings::keypoints_ms},
    {"descriptors", &InsertTimings::descriptors_ms},
    {"match_register", &InsertTimings::match_register_ms},
    {"model_verify", &InsertTimings::model_verify_ms},
    {"scene_verify", &InsertTimings::scene_verify_ms}, {"total", &InsertTimings::total_ms},
    {"replace", &InsertTimings::replace_ms},      {"prefilter", &InsertTimings::prefilter_ms},
    {"load", &InsertTimings::load_ms},            {"store", &InsertTimings::store_ms},
    {"writer_wait", &InsertTimings::writer_wait_ms},
    {"writer_hold", &InsertTimings::writer_hold_ms}};

inline InsertTimings& InsertTimings::operator+=(const InsertTimings& o) {
  for (const auto& [name, member] : kInsertStages) this->*member += o.*member;
  return *this;
}

struct InsertReport {
  // The segment cannot be a model (model::SegmentModel: no surface at the mesh weight): it is
  // stored as a raw segment and replaces its earlier contribution, but no model holds it
  // (model_id 0). Not an error.
  bool unusable = false;
  std::string unusable_reason;
  int64_t model_id = 0;          // the model now holding the segment
  bool merged = false;           // merged into an existing model
  bool planar = false;
  bool structure = false;        // room structure (core/model/structure.h): never matched
  // The smaller in-plane span of the segment's best plane grown through its session's scene
  // (0: not grown: structure already, too little of it on one plane, or no scene).
  float grown_plane_span_m = 0.0f;
  bool matchable = false;
  bool replaced_earlier = false; // the segment's key had been inserted before
  // Replacing that earlier contribution emptied this model, and the store removed it (0: none).
  // The segment is now held by model_id (0 when unusable).
  int64_t removed_model = 0;
  // Merged: the segment grids fused to build the merged model (1: the segment's own, fused into
  // the stored model's grid; the model's every segment when it was rebuilt from them), plus those
  // of each co-accepted model joined to it (its segments, fused in after the merged model's).
  size_t merge_fused_segments = 0;
  size_t candidates = 0;         // after the prefilter, readable
  size_t unreadable_candidates = 0;  // prefilter candidates whose stored data failed to load
  std::vector<CandidateResult> results;  // one per candidate, in candidate order
  // DatabaseParams::merge_co_accepted: the other candidates that accepted the segment, each
  // checked against model_id after the merge (its registration from that transform), in
  // candidate order; the accepted ones were merged into model_id (now in state merged).
  std::vector<CandidateResult> co_accepted;
  // The ids of those merged into model_id (the accepted entries of co_accepted).
  std::vector<int64_t> absorbed() const {
    std::vector<int64_t> ids;
    for (const auto& r : co_accepted) {
      if (r.accepted) ids.push_back(r.model_id);
    }
    return ids;
  }
  InsertTimings timings;
  // ObjectDatabase::measurePrefilterRecall only (else empty): the prefilter's candidate ids as
  // the insert used them, and those of the exhaustive vote, most voted first.
  std::vector<int64_t> prefilter_candidates, exhaustive_candidates;
  // measurePrefilterRecall only: the short list the insert's vote ran over (empty with
  // DatabaseParams::shortlist 0), and every matchable stored model ranked by global similarity
  // to the segment's model, most similar first (the short list is its first `shortlist`).
  std::vector<int64_t> shortlist, global_ranking;
};

// "What is this?" (ObjectDatabase::match): a segment checked against the stored models as an
// insert checks it, nothing written.
struct MatchReport {
  // As InsertReport's: a segment with no surface at the mesh weight has no model (not an error),
  // a planar or structure one is not matched (matchable false, no results).
  bool unusable = false;
  std::string unusable_reason;
  bool planar = false, structure = false, matchable = false;
  size_t points = 0, keypoints = 0;  // the segment's model: surface points, described keypoints
  // The models the descriptor vote ran over (DatabaseParams::shortlist; empty with shortlist 0:
  // every model), and the vote's candidates, each evaluated (registration, model check, colour,
  // scene check at every pose of the candidate and of a stored query model), no
  // stop_after_accepted.
  std::vector<int64_t> shortlist;
  // Accepted first, the lowest e_TSDF first; then the others by how far they got (rejected at
  // the scene check, by colour, at the model check, at registration), in vote order within each.
  // A result's registration.T_target_source takes the segment frame into the candidate's model
  // frame.
  std::vector<CandidateResult> results;
  size_t unreadable_candidates = 0;  // candidates whose stored data failed to load (skipped)
  InsertTimings timings;             // P, K, D, the prefilter, loading and the candidates' steps
};

class ObjectDatabase {
 public:
  // Params are validated. The store outlives the database. The database keeps every matchable
  // model's global descriptor in memory (and, with DatabaseParams::shortlist 0, its local
  // descriptors), loaded here; it is the store's only writer, or, on a store
  // with several (ModelStore::lockWriter), it catches up on the others' changes each time it
  // takes the writer lock, before it matches (object_database_sync.cpp).
  static StatusOr<std::unique_ptr<ObjectDatabase>> create(const Params& params, ModelStore* store);

  // Algorithm 1 for one raw segment of `session`. A segment whose (session, label) was inserted
  // before replaces its earlier contribution (the model it went into is rebuilt without it).
  // Every pose of both models is verified against its session's scene: from `live` first, else
  // the store; a pose with neither rejects the candidate (counted in scenes_missing).
  StatusOr<InsertReport> insertSegment(const std::string& session, const gsm::RawSegment& segment,
                                       const LiveScenes& live = {});
  // Takes back segment (session, label), which the GSM withdrew (merged into another label, or
  // lost its voxels to others: gsm::Gsm::takeWithdrawn): the model that holds it is rebuilt
  // without it, or removed when it was its only segment. The raw segment stays stored, as a
  // record of what was extracted.
  struct Withdrawal {
    // The model that held the segment; 0 when the database did not hold it (never inserted: too
    // small, unusable, or failed to build).
    int64_t model_id = 0;
    bool removed = false;  // it was that model's only segment: the store removed the model
  };
  StatusOr<Withdrawal> withdrawSegment(const std::string& session, gsm::Label label);

  // "What is this?": the segment's model (query_segment.h makes segments of depth images and
  // clouds) matched against every stored model an insert would consider, each candidate
  // evaluated as an insert evaluates it; nothing is written. Its frame is the segment's
  // (segment.T_world_segment places it in the query's frame). The model's structure is judged
  // from the segment alone (no session's scene to grow its plane through). Safe alongside
  // inserts (it reads what they write under the same locks).
  StatusOr<MatchReport> match(const gsm::RawSegment& segment, const LiveScenes& live = {});
  // The same for stored model `model_id` against the others ("find similar"): its own poses are
  // verified against their scenes too, as a merge would. NOT_FOUND: no such model, or not
  // active.
  StatusOr<MatchReport> matchModel(int64_t model_id, const LiveScenes& live = {});

  // Candidate model ids for a model (the prefilter alone; for benchmarks of its recall).
  // `exhaustive`: the vote over every stored descriptor's exact distance (linear in their
  // number), whatever DatabaseParams::prefilter_epsilon says.
  // Without `exhaustive`, the vote runs over the DatabaseParams::shortlist models of the most
  // similar global descriptors (written to `shortlist` when given; with shortlist 0 over every
  // model, `shortlist` left alone).
  StatusOr<std::vector<int64_t>> candidatesFor(const model::ObjectModel& model,
                                               bool exhaustive = false,
                                               std::vector<int64_t>* shortlist = nullptr);
  // For benchmarks: every insert also runs the exhaustive vote and reports both candidate lists
  // (InsertReport::prefilter_candidates, exhaustive_candidates), so the recall of an approximate
  // prefilter can be measured on the inserts as they happen.
  void measurePrefilterRecall(bool on) { measure_prefilter_ = on; }

 private:
  ObjectDatabase(const Params& params, ModelStore* store);
  model::ModelBuildParams buildParams(float observation_depth_m) const;
  // A model from the raw segments of `observations`, fused in their order (its id: `id`).
  StatusOr<model::ObjectModel> buildFromObservations(std::vector<model::Observation> observations,
                                                     int64_t id);
  // `target` extended by more segments: `observations` are target's, then the added ones. Their
  // segments are fused into the stored grid, not every segment again; the same model as
  // buildFromObservations(observations) (object_database_build.cpp). The added segments are
  // read from the store, but `in_hand` (the one being inserted). `fused`: segment grids fused.
  StatusOr<model::ObjectModel> extendModel(const model::ObjectModel& target,
                                           std::vector<model::Observation> observations,
                                           const RawSegmentRecord* in_hand, size_t* fused);
  // Takes the segment `key` out of model `model_id`; true when that emptied the model, which the
  // store then removed.
  StatusOr<bool> removeContribution(const SegmentKey& key, int64_t model_id);
  // The scene map of `session`: the live one when `live` has it, else the store's (null: none).
  StatusOr<std::shared_ptr<const tsdf::TsdfLayer>> sceneOf(const std::string& session,
                                                           const LiveScenes& live) const;
  // The smaller span of `incoming`'s best plane grown through `session`'s scene (live first).
  StatusOr<float> growInScene(const std::string& session, const model::ObjectModel& incoming,
                              const LiveScenes& live);
  // e*_ICP and e*_TSDF for a segment seen from depth_m in a session whose depth noise measured
  // `noise_scale` times the model's σ (gsm::RawSegment; MergingParams::noise_sigmas). Either 0:
  // the paper's thresholds.
  struct Thresholds {
    double icp_m = 0.0, tsdf_m = 0.0;
    float depth_m = 0.0f, noise_scale = 0.0f;  // what they were loosened for (reasons, logs)
  };
  Thresholds thresholdsFor(float depth_m, float noise_scale) const;
  // `thresholds`: the incoming segment's (the paper's for a join of stored models).
  CandidateResult evaluate(const model::ObjectModel& incoming, const model::ObjectModel& candidate,
                           const Thresholds& thresholds, const LiveScenes& live,
                           InsertTimings* timings);
  // The checks after registration (out->registration accepted): model to model on the grids,
  // the colours, then the merged grid at every pose of both against its scene. Fills the rest
  // of `out`.
  void verifyRegistered(const model::ObjectModel& incoming, const model::ObjectModel& candidate,
                        const Thresholds& thresholds, const LiveScenes& live,
                        InsertTimings* timings, CandidateResult* out);
  // match() and matchModel() once the query's model is built (object_database_match.cpp).
  Status matchIncoming(const model::ObjectModel& incoming, const Thresholds& thresholds,
                       const LiveScenes& live, MatchReport* report);
  // DatabaseParams::merge_co_accepted, after the segment merged into `merged` (best): the other
  // accepted candidates (`loaded` in report->results' order) verified onto it and merged in.
  Status absorbCoAccepted(std::shared_ptr<const model::ObjectModel> merged,
                          const CandidateResult& best,
                          const std::vector<std::shared_ptr<const model::ObjectModel>>& loaded,
                          const LiveScenes& live, InsertReport* report);
  std::shared_ptr<const matching::DescriptorIndex> indexOf(const model::ObjectModel& model);
  // The short list for a global descriptor (model `exclude` left out); mutex_ held.
  std::vector<int64_t> shortlistFor(const std::vector<float>& global, int64_t exclude) const;
  // Fills the global index from the entries; a global descriptor missing in the store (an older
  // schema, another codebook version) is computed from the local ones and written back
  // (object_database_retrieval.cpp).
  Status loadGlobalIndex(const std::vector<MatchEntry*>& matchable);
  // The local descriptors of models `ids` (a short list), from the cache or the store; mutex_
  // held. forgetDescriptors drops a changed model's.
  StatusOr<std::vector<std::shared_ptr<const std::vector<model::Fpfh>>>> cachedDescriptors(
      const std::vector<int64_t>& ids);
  void forgetDescriptors(int64_t id);
  // Model `id` decoded: from the cache of the kCachedModels most recently loaded (candidates
  // recur: every insert of a repeated object meets the same models), else from the store.
  StatusOr<std::shared_ptr<const model::ObjectModel>> loadModel(int64_t id);
  // A model this database added, replaced (entry given) or removed (no entry): drops its cached
  // index and updates the prefilter's entries.
  void changed(int64_t model_id, std::optional<MatchEntry> entry);

  Params params_;
  ModelStore* store_;
  std::mutex mutex_;  // guards the caches below
  // Each model's descriptor index, with a fingerprint of the descriptors it was built from.
  struct CachedIndex {
    uint64_t fingerprint = 0;
    std::shared_ptr<const matching::DescriptorIndex> index;
  };
  std::map<int64_t, CachedIndex> indices_;
  // Decoded models, most recently used first; a model's entry goes when it changes (changed()).
  static constexpr size_t kCachedModels = 32;
  std::list<std::shared_ptr<const model::ObjectModel>> models_;
  std::map<SegmentKey, int64_t> segment_model_;  // which model holds each segment
  // With DatabaseParams::shortlist 0 only: the descriptors of every matchable stored model,
  // updated by every change this database makes and by the changes other writers made (no
  // rebuild per insert). With a short list the local descriptors stay in the store.
  PrefilterIndex prefilter_;
  // The same models' global descriptors: the short list (DatabaseParams::shortlist).
  GlobalIndex global_;
  // With a short list: recently voted-over models' local descriptors (mutex_), least recently
  // used first out once they hold more than kCachedDescriptors (about 130 MB of FPFH).
  static constexpr size_t kCachedDescriptors = 1000000;
  struct CachedDescriptors {
    std::shared_ptr<const std::vector<model::Fpfh>> descriptors;
    std::list<int64_t>::iterator lru;
  };
  std::map<int64_t, CachedDescriptors> descriptor_cache_;
  std::list<int64_t> descriptor_lru_;  // most recently used first
  size_t cached_descriptors_ = 0;

  // Several writers (object_database_sync.cpp). insertSegment and withdrawSegment run their
  // *Locked body under the store's writer lock, taken by beginWrite, which first applies the
  // changes other writers made since applied_seq_; endWrite records the sequence after this
  // database's own changes.
  StatusOr<std::unique_ptr<WriterLock>> beginWrite();
  void endWrite(const WriterLock* lock);
  void applyChanges(const ModelChanges& changes);
  // The part of an insert that depends on no stored model: the segment's model with its
  // planarity and structure tests (report: planar, structure, matchable, grown span, the P/K/D
  // timings). It runs before the writer lock, so that writers build their models in parallel.
  struct Prepared {
    Status error;  // the build failed (returned once the raw segment is stored)
    std::optional<model::ObjectModel> incoming;  // empty without an error: unusable
    InsertReport report;
  };
  Prepared prepareInsert(const std::string& session, const gsm::RawSegment& segment,
                         const LiveScenes& live);
  // The rest under the lock. A segment whose model could not be built, or that is unusable,
  // still replaces its earlier contribution and is stored as raw segment before the build's
  // error (or the unusable report) is returned.
  StatusOr<InsertReport> insertLocked(const std::string& session, const gsm::RawSegment& segment,
                                      const LiveScenes& live, Prepared prepared);
  StatusOr<Withdrawal> withdrawLocked(const std::string& session, gsm::Label label);
  int64_t applied_seq_ = 0;
  bool measure_prefilter_ = false;
};

}  // namespace objdb::database
