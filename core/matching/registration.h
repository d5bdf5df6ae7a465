// Matching and registration of two object models (paper §III-C.3): FPFH descriptors matched
// through a kd-tree (k_NN best per keypoint above t_sim), RANSAC over the matches for a coarse
// transform (rejected when no consistent set exists), point-to-plane ICP for the fine one,
// rejected when its RMSE exceeds e*_ICP. PCL stays inside registration.cpp.
//
// Choices the paper leaves open: RANSAC is ours (estimateCoarseAlignment: PCL's sample
// consensus keeps one hypothesis by keypoint support, and a symmetric part of an object offers a
// wrong one with as much support as the right one); e_ICP is the point-to-plane RMSE over the
// pairs within the correspondence distance.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "core/common/params.h"
#include "core/common/transform.h"
#include "core/model/object_model.h"

namespace objdb::matching {

// Descriptor similarity in [0, 1]: 1 − ‖a − b‖ / (‖a‖ + ‖b‖) (1 = identical). Our definition:
// the paper gives t_sim = 0.4 without one.
float fpfhSimilarity(const model::Fpfh& a, const model::Fpfh& b);

// A kd-tree over one model's descriptors, built once and queried by every new model. With
// `epsilon` > 0 the search is approximate (FLANN's (1 + ε) bound: a branch is skipped unless it
// may hold a descriptor closer than the k-th found so far divided by 1 + ε), and deterministic.
class DescriptorIndex {
 public:
  // Takes the descriptors (pass a copy to keep them): one FLANN kd-tree over them, which keeps
  // one copy of its own in leaf order.
  explicit DescriptorIndex(std::vector<model::Fpfh> descriptors, float epsilon = 0.0f);
  ~DescriptorIndex();
  DescriptorIndex(DescriptorIndex&&) noexcept;
  DescriptorIndex& operator=(DescriptorIndex&&) noexcept;

  size_t size() const { return descriptors_.size(); }
  const std::vector<model::Fpfh>& descriptors() const { return descriptors_; }
  // Up to k nearest descriptors: (index, similarity), most similar first.
  std::vector<std::pair<uint32_t, float>> nearest(const model::Fpfh& query, int k) const;

 private:
  struct Tree;
  std::vector<model::Fpfh> descriptors_;
  std::unique_ptr<Tree> tree_;
};

struct DescriptorMatch {
  uint32_t source = 0, target = 0;  // keypoint indices (positions in keypoint_indices)
  float similarity = 0.0f;
};
// For every source keypoint the k_NN most similar target descriptors with similarity ≥ t_sim.
std::vector<DescriptorMatch> matchDescriptors(const std::vector<model::Fpfh>& source,
                                              const DescriptorIndex& target,
                                              const MatchingParams& params);

// The coarse step: RANSAC over matched keypoint pairs (from[k] ↔ to[k]). Samples of three
// pairs whose pairwise distances agree are fitted (Umeyama, no scale) and counted; the best
// supported hypotheses are refined on their inliers and the winner is the one the target's TSDF
// agrees with most: source surface points landing on observed target surface count for it,
// those landing in observed free space or inside count against it (keypoints alone cannot tell
// a symmetric wrong hypothesis from the right one). Deterministic (fixed seed).
struct CoarseAlignment {
  Transform T_target_source = Transform::Identity();
  size_t inliers = 0;       // keypoint pairs within the inlier distance (0: no hypothesis)
  size_t hypotheses = 0;    // samples with at least ransac_min_inliers support
  double fitness = 0.0;     // (agreeing − disagreeing) / sampled source points, in [−1, 1]
};
CoarseAlignment estimateCoarseAlignment(const std::vector<Eigen::Vector3f>& from,
                                        const std::vector<Eigen::Vector3f>& to,
                                        const PointCloud& source_cloud,
                                        const tsdf::TsdfLayer& target_grid,
                                        const MatchingParams& params);

struct Registration {
  bool accepted = false;
  std::string reason;                                   // why not
  Transform T_target_source = Transform::Identity();    // T_{j,i} = T_fine · T_coarse
  Transform T_coarse = Transform::Identity();
  size_t matches = 0, inliers = 0;                      // descriptor matches, RANSAC inliers
  size_t hypotheses = 0;                                // RANSAC samples with enough support
  double coarse_agreement = 0.0;                        // CoarseAlignment::fitness
  double icp_rmse = 0.0;   // e_ICP: point-to-plane RMSE over the final pairs, metres
  size_t icp_pairs = 0;    // source points paired within the ICP correspondence distance
  double match_ms = 0, ransac_ms = 0, icp_ms = 0;
};

// Registers `source` (s_i) onto `target` (s_j). `target_index` must be built from
// target.descriptors. Both models must be matchable.
Registration registerModels(const model::ObjectModel& source, const model::ObjectModel& target,
                            const DescriptorIndex& target_index, const MatchingParams& params);

// The fine step alone: point-to-plane ICP of `source` onto `target` from `T_initial` (kept as
// T_coarse), accepted when it converges with e_ICP ≤ e*_ICP. registerModels ends with it; the
// database uses it where a transform is already known (two models that each took one segment).
Registration refineRegistration(const model::ObjectModel& source, const model::ObjectModel& target,
                                const Transform& T_initial, const MatchingParams& params);

}  // namespace objdb::matching
