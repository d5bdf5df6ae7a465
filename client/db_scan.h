// The database's placements seen in the sessions' frames, shared by `objdb report` and
// `objdb eval`: every model's placements, the frame that sees each best (most model points
// landing on pixels whose measured depth agrees) and, where the frames have ground-truth
// instances, which instances those points fall on.
#pragma once

#include <cstddef>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "core/common/frame.h"
#include "core/common/intrinsics.h"
#include "core/common/status.h"
#include "core/common/transform.h"
#include "core/database/object_database.h"
#include "core/io/dataset.h"
#include "storage/store.h"

namespace objdb::cli {

inline constexpr size_t kMaxScanPoints = 3000;  // model points projected per placement

// The instance a model point fell on most often over the frames (a running majority vote,
// Boyer–Moore: exact when one instance holds more than half of its votes; 0 = background).
struct PointVote {
  int instance = 0;
  int lead = 0;  // votes for `instance` beyond the others (0: no vote yet, or a tie)
  bool voted = false;
  void add(int id) {
    voted = true;
    if (lead == 0) instance = id;
    lead += id == instance ? 1 : -1;
  }
};

struct Placement {
  std::string session;
  Transform T_world_object;
  size_t best_frame = 0;
  size_t best_hits = 0;
  std::map<int, size_t> votes;  // ground-truth instance id → points on it, over all frames
  std::vector<PointVote> point_votes;  // per model point (Row::points), where frames have truth
};

struct Row {
  storage::ModelSummary summary;
  std::vector<Eigen::Vector3f> points;  // model frame, at most kMaxScanPoints
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();  // model::placeCentre (its bounds' middle)
  std::vector<database::MergeRecord> merges;
  std::vector<Placement> placements;
};

// Placements a and b of `row` are one (model::samePlace): one surface under two GSM labels.
bool samePlace(const Row& row, const Placement& a, const Placement& b);
// Distinct places among the row's placements (model::countPlaces).
size_t places(const Row& row);

// Points of `points` (model frame) placed by T_camera_object that land on a pixel of `frame`
// whose depth agrees (within max(3 cm, 2 % of the depth)); with `draw`, those points are drawn
// onto it in `colour`; with `votes`, the ground-truth instance under each is counted, and with
// `point_votes` (aligned with `points`) each point's own vote is added.
size_t depthAgreeingPoints(const std::vector<Eigen::Vector3f>& points,
                           const Transform& T_camera_object, const Frame& frame,
                           const Intrinsics& k, cv::Mat* draw = nullptr,
                           const cv::Scalar& colour = {},
                           std::map<int, size_t>* votes = nullptr,
                           std::vector<PointVote>* point_votes = nullptr);

// The active models with at least `min_placements` placements, most placements first, at most
// `max_rows`, with their sampled clouds and merge records.
StatusOr<std::vector<Row>> loadRows(const storage::Store& store, size_t min_placements,
                                    size_t max_rows);

// One pass over each session's frames (every `every`-th): the best frame of every placement and
// the instance votes of its depth-agreeing points. `datasets`: session name → folder; the opened
// datasets are returned in `opened` when it is not null.
Status scanFrames(const std::map<std::string, std::string>& datasets, size_t every,
                  std::vector<Row>* rows,
                  std::map<std::string, std::unique_ptr<io::Dataset>>* opened);

// Ground truth of a placement: the instance most of its depth-agreeing points fell on (0: none
// with >= 50 % of them); `purity` is that share.
int truthOf(const Placement& p, double* purity);

}  // namespace objdb::cli
