// The only translation unit of core/matching that includes PCL (registration headers are the
// heaviest: ~30 s and 1.5 GB to compile).
#include "core/matching/registration.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <random>

#include <Eigen/Geometry>

#include <pcl/console/print.h>
#include <flann/flann.hpp>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>
#include <pcl/registration/icp.h>
#include <pcl/registration/transformation_estimation_point_to_plane_lls.h>
#include <pcl/search/kdtree.h>

#include "absl/strings/str_format.h"

namespace objdb::matching {
namespace {

using Clock = std::chrono::steady_clock;
double msSince(Clock::time_point t) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

double norm(const model::Fpfh& a) {
  double s = 0.0;
  for (float v : a) s += double(v) * double(v);
  return std::sqrt(s);
}

// Every `stride`-th point with its normal.
pcl::PointCloud<pcl::PointNormal>::Ptr withNormals(const PointCloud& cloud, size_t stride = 1) {
  auto out = std::make_shared<pcl::PointCloud<pcl::PointNormal>>();
  out->reserve(cloud.points.size() / stride + 1);
  for (size_t i = 0; i < cloud.points.size(); i += stride) {
    pcl::PointNormal p;
    p.getVector3fMap() = cloud.points[i];
    p.getNormalVector3fMap() = cloud.normals[i];
    p.curvature = 0.0f;
    out->push_back(p);
  }
  return out;
}

// Point-to-plane least squares that never hands ICP a non-finite step. On a degenerate set of
// correspondences (a few pairs whose normals span no 3-D system) PCL's solve can return NaN;
// ICP would then move every source point to NaN and PCL's kd-tree asserts on them, which would
// end the process. A non-finite step is replaced by no step: ICP stops there (converged, the
// transform unchanged) and e_ICP judges that transform like any other.
class FiniteStepPointToPlane
    : public pcl::registration::TransformationEstimationPointToPlaneLLS<pcl::PointNormal,
                                                                        pcl::PointNormal, float> {
 public:
  using Base = pcl::registration::TransformationEstimationPointToPlaneLLS<pcl::PointNormal,
                                                                          pcl::PointNormal, float>;
  using Base::estimateRigidTransformation;
  void estimateRigidTransformation(const pcl::PointCloud<pcl::PointNormal>& source,
                                   const pcl::PointCloud<pcl::PointNormal>& target,
                                   const pcl::Correspondences& correspondences,
                                   Matrix4& transformation) const override {
    Base::estimateRigidTransformation(source, target, correspondences, transformation);
    if (!transformation.allFinite()) {
      ++degenerate_steps;
      transformation.setIdentity();
    }
  }
  mutable size_t degenerate_steps = 0;
};

}  // namespace

float fpfhSimilarity(const model::Fpfh& a, const model::Fpfh& b) {
  double d = 0.0;
  for (size_t i = 0; i < a.size(); ++i) {
    const double e = double(a[i]) - double(b[i]);
    d += e * e;
  }
  const double scale = norm(a) + norm(b);
  return scale > 0.0 ? float(1.0 - std::sqrt(d) / scale) : 1.0f;
}

// FLANN's single kd-tree with 15 points per leaf, as PCL's KdTreeFLANN builds it, but on the
// descriptors themselves: PCL would keep its own point cloud and float array besides (the
// prefilter held six copies of each descriptor, 841 bytes for 132; now two). The tree and the
// search are the same, so are the neighbours. FLANN keeps its own copy in leaf order: without it
// a leaf's descriptors are read scattered, and the prefilter's queries took three times as long
// at 10,000 models.
struct DescriptorIndex::Tree {
  Tree(flann::Matrix<float> data, float epsilon)
      : index(data, flann::KDTreeSingleIndexParams(15, /*reorder=*/true)),
        params(-1, epsilon) {
    index.buildIndex();
  }
  flann::Index<flann::L2_Simple<float>> index;
  flann::SearchParams params;
};

static_assert(sizeof(model::Fpfh) == 33 * sizeof(float), "descriptors are searched in place");

DescriptorIndex::DescriptorIndex(std::vector<model::Fpfh> descriptors, float epsilon)
    : descriptors_(std::move(descriptors)) {
  if (descriptors_.empty()) return;
  tree_ = std::make_unique<Tree>(
      flann::Matrix<float>(descriptors_.front().data(), descriptors_.size(), 33), epsilon);
}

DescriptorIndex::~DescriptorIndex() = default;
DescriptorIndex::DescriptorIndex(DescriptorIndex&&) noexcept = default;
DescriptorIndex& DescriptorIndex::operator=(DescriptorIndex&&) noexcept = default;

std::vector<std::pair<uint32_t, float>> DescriptorIndex::nearest(const model::Fpfh& query,
                                                                 int k) const {
  std::vector<std::pair<uint32_t, float>> out;
  if (descriptors_.empty() || k <= 0) return out;
  const size_t n = std::min(size_t(k), descriptors_.size());
  model::Fpfh q = query;
  std::vector<size_t> indices(n);
  std::vector<float> squared(n);
  flann::Matrix<size_t> indices_row(indices.data(), 1, n);
  flann::Matrix<float> squared_row(squared.data(), 1, n);
  const int found = tree_->index.knnSearch(flann::Matrix<float>(q.data(), 1, q.size()),
                                           indices_row, squared_row, n, tree_->params);
  for (int i = 0; i < found; ++i) {
    const uint32_t d = uint32_t(indices[size_t(i)]);
    out.emplace_back(d, fpfhSimilarity(query, descriptors_[d]));
  }
  return out;
}

std::vector<DescriptorMatch> matchDescriptors(const std::vector<model::Fpfh>& source,
                                              const DescriptorIndex& target,
                                              const MatchingParams& params) {
  std::vector<DescriptorMatch> matches;
  for (size_t s = 0; s < source.size(); ++s) {
    for (const auto& [t, similarity] : target.nearest(source[s], params.k_nn)) {
      if (similarity >= params.similarity_threshold) {
        matches.push_back({uint32_t(s), t, similarity});
      }
    }
  }
  return matches;
}

CoarseAlignment estimateCoarseAlignment(const std::vector<Eigen::Vector3f>& from,
                                        const std::vector<Eigen::Vector3f>& to,
                                        const PointCloud& source_cloud,
                                        const tsdf::TsdfLayer& target_grid,
                                        const MatchingParams& params) {
  CoarseAlignment result;
  const size_t n = std::min(from.size(), to.size());
  if (n < 3) return result;
  const float threshold = params.ransac_inlier_distance_m;
  const float threshold2 = threshold * threshold;
  auto fit = [&](const std::vector<size_t>& pairs) {
    Eigen::Matrix3Xf a(3, pairs.size()), b(3, pairs.size());
    for (size_t k = 0; k < pairs.size(); ++k) {
      a.col(Eigen::Index(k)) = from[pairs[k]];
      b.col(Eigen::Index(k)) = to[pairs[k]];
    }
    return Eigen::Matrix4f(Eigen::umeyama(a, b, false));
  };
  auto inliersOf = [&](const Eigen::Matrix4f& T, std::vector<size_t>* out) {
    const Eigen::Matrix3f R = T.topLeftCorner<3, 3>();
    const Eigen::Vector3f tr = T.topRightCorner<3, 1>();
    size_t count = 0;
    for (size_t k = 0; k < n; ++k) {
      if ((R * from[k] + tr - to[k]).squaredNorm() < threshold2) {
        ++count;
        if (out) out->push_back(k);
      }
    }
    return count;
  };

  // Sampling: three matches whose pairwise distances agree within 10 % on both sides (rigid
  // motions keep them; the check rejects most bad samples before any fit).
  struct Hypothesis {
    Eigen::Matrix4f T;
    size_t inliers;
  };
  std::vector<Hypothesis> best;  // the most supported, at most kKeep
  constexpr size_t kKeep = 8;
  std::mt19937 rng(20181001u);  // fixed: registration is deterministic
  std::uniform_int_distribution<size_t> pick(0, n - 1);
  const float min_edge = 2.0f * threshold;
  for (int it = 0; it < params.ransac_iterations; ++it) {
    const size_t i = pick(rng), j = pick(rng), k = pick(rng);
    if (i == j || j == k || i == k) continue;
    bool similar = true;
    const size_t idx[3] = {i, j, k};
    for (int e = 0; e < 3 && similar; ++e) {
      const size_t p = idx[e], q = idx[(e + 1) % 3];
      const float ds = (from[p] - from[q]).norm(), dt = (to[p] - to[q]).norm();
      similar = ds > min_edge && dt > min_edge && std::abs(ds - dt) < 0.1f * std::max(ds, dt);
    }
    if (!similar) continue;
    const Eigen::Matrix4f T = fit({i, j, k});
    if (!T.allFinite()) continue;
    const size_t support = inliersOf(T, nullptr);
    if (support < size_t(params.ransac_min_inliers)) continue;
    ++result.hypotheses;
    if (best.size() < kKeep || support > best.back().inliers) {
      best.push_back({T, support});
      std::stable_sort(best.begin(), best.end(),
                       [](const auto& x, const auto& y) { return x.inliers > y.inliers; });
      if (best.size() > kKeep) best.pop_back();
    }
  }
  if (best.empty()) return result;

  // The keypoints alone cannot tell a right hypothesis from a symmetric wrong one with as much
  // support, and surface-to-surface fitness prefers whatever tucks a partial view inside the
  // other's coverage. The target's TSDF can: each candidate (refined on its inliers) maps the
  // source surface into the target grid; a point where the target observed surface agrees, one
  // where it observed free space or inside disagrees, unobserved space is neutral.
  double best_score = -2.0;
  const size_t stride = std::max<size_t>(1, source_cloud.points.size() / 1000);
  for (const Hypothesis& h : best) {
    std::vector<size_t> support;
    inliersOf(h.T, &support);
    const Eigen::Matrix4f T = support.size() >= 3 ? fit(support) : h.T;
    const Eigen::Matrix3f R = T.topLeftCorner<3, 3>();
    const Eigen::Vector3f tr = T.topRightCorner<3, 1>();
    long agree = 0, disagree = 0, tried = 0;
    for (size_t p = 0; p < source_cloud.points.size(); p += stride) {
      ++tried;
      float d = 0.0f;
      if (!target_grid.interpolateDistance(R * source_cloud.points[p] + tr, &d)) continue;
      if (std::abs(d) < threshold) {
        ++agree;
      } else {
        ++disagree;
      }
    }
    const double score = tried ? double(agree - disagree) / double(tried) : 0.0;
    if (score > best_score) {
      best_score = score;
      result.T_target_source = Transform(T.cast<double>());
      result.inliers = inliersOf(T, nullptr);
      result.fitness = score;
    }
  }
  // Orthonormalise the float round trip.
  const Eigen::Quaterniond q(result.T_target_source.rotation());
  result.T_target_source.linear() = q.normalized().toRotationMatrix();
  return result;
}

namespace {
// ICP from r->T_coarse; fills the fine transform, e_ICP and the verdict.
void refineInto(const model::ObjectModel& source, const model::ObjectModel& target,
                const MatchingParams& params, Registration* out) {
  Registration& r = *out;
  // PCL reports too few ICP pairs as an error on stderr; here that outcome is a rejection with
  // its reason, so PCL's console stays quiet.
  static const bool quiet = [] {
    pcl::console::setVerbosityLevel(pcl::console::L_ALWAYS);
    return true;
  }();
  (void)quiet;
  // Point-to-plane ICP from the initial (coarse) transform.
  const auto t = Clock::now();
  pcl::IterativeClosestPointWithNormals<pcl::PointNormal, pcl::PointNormal> icp;
  const auto step = std::make_shared<FiniteStepPointToPlane>();
  icp.setTransformationEstimation(step);
  if (!r.T_coarse.matrix().allFinite()) {
    r.reason = "the coarse transform is not finite";
    return;
  }
  // ICP moves the source: a thinned source (at most icp_max_source_points) against the full
  // target keeps its cost bounded without losing the target's detail.
  icp.setInputSource(withNormals(
      source.cloud, std::max<size_t>(1, (source.cloud.points.size() +
                                         size_t(params.icp_max_source_points) - 1) /
                                            size_t(params.icp_max_source_points))));
  icp.setInputTarget(withNormals(target.cloud));
  icp.setMaxCorrespondenceDistance(params.icp_max_correspondence_m);
  icp.setMaximumIterations(params.icp_iterations);
  // Converged when an iteration moves the source by less than 0.1 mm (PCL compares the squared
  // translation with the epsilon) and turns it by less than its default rotation threshold.
  icp.setTransformationEpsilon(1e-8);
  icp.setEuclideanFitnessEpsilon(1e-9);
  pcl::PointCloud<pcl::PointNormal> aligned;
  icp.align(aligned, r.T_coarse.matrix().cast<float>());
  r.icp_ms = msSince(t);
  if (!icp.hasConverged()) {
    r.reason = "ICP did not converge";
    return;
  }
  r.T_target_source = Transform(icp.getFinalTransformation().cast<double>());
  // Orthonormalise the float round trip so the transform validates as a rigid motion.
  const Eigen::Quaterniond q(r.T_target_source.rotation());
  r.T_target_source.linear() = q.normalized().toRotationMatrix();
  // e_ICP: point-to-plane RMSE over the source points whose nearest target point lies within
  // the ICP correspondence distance (what point-to-plane ICP minimises). Point-to-point RMSE
  // would charge a partial view for surface that simply continues beyond the other view.
  {
    pcl::search::KdTree<pcl::PointNormal> tree;
    tree.setInputCloud(icp.getInputTarget());
    const pcl::PointCloud<pcl::PointNormal>& target_cloud = *icp.getInputTarget();
    std::vector<int> nearest(1);
    std::vector<float> squared(1);
    const double max2 = double(params.icp_max_correspondence_m) * params.icp_max_correspondence_m;
    double sum = 0.0;
    size_t pairs = 0;
    for (const auto& p : aligned) {
      if (tree.nearestKSearch(p, 1, nearest, squared) != 1 || double(squared[0]) > max2) continue;
      const pcl::PointNormal& q = target_cloud[size_t(nearest[0])];
      const double e = double((p.getVector3fMap() - q.getVector3fMap()).dot(q.getNormalVector3fMap()));
      sum += e * e;
      ++pairs;
    }
    r.icp_pairs = pairs;
    r.icp_rmse = pairs ? std::sqrt(sum / double(pairs)) : INFINITY;
  }
  if (!(r.icp_rmse <= double(params.icp_max_rmse_m))) {
    r.reason = absl::StrFormat("e_ICP %.4f m > e*_ICP %.4f m", r.icp_rmse, params.icp_max_rmse_m);
    return;
  }
  r.accepted = true;
}
}  // namespace

Registration registerModels(const model::ObjectModel& source, const model::ObjectModel& target,
                            const DescriptorIndex& target_index, const MatchingParams& params) {
  Registration r;
  auto t = Clock::now();
  const std::vector<DescriptorMatch> matches =
      matchDescriptors(source.descriptors, target_index, params);
  r.matches = matches.size();
  r.match_ms = msSince(t);
  if (matches.size() < size_t(params.ransac_min_inliers)) {
    r.reason = absl::StrFormat("%d descriptor matches < %d needed", matches.size(),
                               params.ransac_min_inliers);
    return r;
  }

  // RANSAC over the matches: a consistent set and the coarse transform.
  t = Clock::now();
  std::vector<Eigen::Vector3f> from, to;
  for (const auto& m : matches) {
    from.push_back(source.keypoint(m.source));
    to.push_back(target.keypoint(m.target));
  }
  const CoarseAlignment coarse = estimateCoarseAlignment(from, to, source.cloud, target.grid, params);
  r.inliers = coarse.inliers;
  r.hypotheses = coarse.hypotheses;
  r.ransac_ms = msSince(t);
  if (coarse.inliers < size_t(params.ransac_min_inliers)) {
    r.reason = absl::StrFormat("RANSAC found %d consistent matches < %d needed", coarse.inliers,
                               params.ransac_min_inliers);
    return r;
  }
  r.T_coarse = coarse.T_target_source;
  r.coarse_agreement = coarse.fitness;
  if (!(coarse.fitness >= double(params.coarse_min_agreement))) {
    r.reason = absl::StrFormat(
        "coarse alignment: the target grid disagrees (agreement %.2f < %.2f)", coarse.fitness,
        params.coarse_min_agreement);
    return r;
  }

  refineInto(source, target, params, &r);
  return r;
}

Registration refineRegistration(const model::ObjectModel& source, const model::ObjectModel& target,
                                const Transform& T_initial, const MatchingParams& params) {
  Registration r;
  r.T_coarse = T_initial;
  refineInto(source, target, params, &r);
  return r;
}

}  // namespace objdb::matching
