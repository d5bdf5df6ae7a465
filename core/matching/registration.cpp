// The only translation unit of core/matching that includes PCL (registration headers are the
// heaviest: see DESIGN.md).
#include "core/matching/registration.h"

#include <chrono>
#include <cmath>

#include <pcl/kdtree/kdtree_flann.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>
#include <pcl/registration/icp.h>
#include <pcl/sample_consensus/msac.h>
#include <pcl/sample_consensus/sac_model_registration.h>
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

pcl::PointCloud<pcl::PointNormal>::Ptr withNormals(const PointCloud& cloud) {
  auto out = std::make_shared<pcl::PointCloud<pcl::PointNormal>>();
  out->reserve(cloud.points.size());
  for (size_t i = 0; i < cloud.points.size(); ++i) {
    pcl::PointNormal p;
    p.getVector3fMap() = cloud.points[i];
    p.getNormalVector3fMap() = cloud.normals[i];
    p.curvature = 0.0f;
    out->push_back(p);
  }
  return out;
}

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

struct DescriptorIndex::Tree {
  pcl::KdTreeFLANN<pcl::FPFHSignature33> kdtree;
};

DescriptorIndex::DescriptorIndex(const std::vector<model::Fpfh>& descriptors)
    : descriptors_(descriptors), tree_(std::make_unique<Tree>()) {
  if (descriptors_.empty()) return;
  auto cloud = std::make_shared<pcl::PointCloud<pcl::FPFHSignature33>>();
  cloud->resize(descriptors_.size());
  for (size_t i = 0; i < descriptors_.size(); ++i) {
    std::copy(descriptors_[i].begin(), descriptors_[i].end(), (*cloud)[i].histogram);
  }
  tree_->kdtree.setInputCloud(cloud);
}

DescriptorIndex::~DescriptorIndex() = default;
DescriptorIndex::DescriptorIndex(DescriptorIndex&&) noexcept = default;
DescriptorIndex& DescriptorIndex::operator=(DescriptorIndex&&) noexcept = default;

std::vector<std::pair<uint32_t, float>> DescriptorIndex::nearest(const model::Fpfh& query,
                                                                 int k) const {
  std::vector<std::pair<uint32_t, float>> out;
  if (descriptors_.empty() || k <= 0) return out;
  pcl::FPFHSignature33 q;
  std::copy(query.begin(), query.end(), q.histogram);
  std::vector<int> indices;
  std::vector<float> squared;
  const int found = tree_->kdtree.nearestKSearch(q, std::min<int>(k, int(descriptors_.size())),
                                                 indices, squared);
  for (int n = 0; n < found; ++n) {
    const uint32_t i = uint32_t(indices[size_t(n)]);
    out.emplace_back(i, fpfhSimilarity(query, descriptors_[i]));
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
  // One point pair per match (a keypoint may appear in up to k_NN matches; PCL's sample
  // consensus wants each sample index once): pair i of `from` goes to pair i of `to`.
  auto from = std::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
  auto to = std::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
  for (const auto& m : matches) {
    const Eigen::Vector3f a = source.keypoint(m.source), b = target.keypoint(m.target);
    from->push_back(pcl::PointXYZ(a.x(), a.y(), a.z()));
    to->push_back(pcl::PointXYZ(b.x(), b.y(), b.z()));
  }
  // MSAC rather than plain RANSAC: a symmetric part of an object offers a wrong hypothesis with
  // as many inliers as the right one; scoring by truncated residuals prefers the precise one.
  auto model = std::make_shared<pcl::SampleConsensusModelRegistration<pcl::PointXYZ>>(from);
  model->setInputTarget(to);
  pcl::MEstimatorSampleConsensus<pcl::PointXYZ> msac(model, params.ransac_inlier_distance_m);
  msac.setMaxIterations(params.ransac_iterations);
  std::vector<int> inliers;
  Eigen::VectorXf coefficients;
  if (msac.computeModel()) {
    msac.getInliers(inliers);
    msac.getModelCoefficients(coefficients);
  }
  r.inliers = inliers.size();
  r.ransac_ms = msSince(t);
  if (inliers.size() < size_t(params.ransac_min_inliers) || coefficients.size() != 16) {
    r.reason = absl::StrFormat("RANSAC found %d consistent matches < %d needed", inliers.size(),
                               params.ransac_min_inliers);
    return r;
  }
  // Least squares over the inliers.
  Eigen::VectorXf refined;
  model->optimizeModelCoefficients(inliers, coefficients, refined);
  const Eigen::Matrix4f coarse = Eigen::Map<const Eigen::Matrix<float, 4, 4, Eigen::RowMajor>>(
      refined.size() == 16 ? refined.data() : coefficients.data());
  r.T_coarse = Transform(coarse.cast<double>());

  // Point-to-plane ICP from the coarse transform.
  t = Clock::now();
  pcl::IterativeClosestPointWithNormals<pcl::PointNormal, pcl::PointNormal> icp;
  icp.setInputSource(withNormals(source.cloud));
  icp.setInputTarget(withNormals(target.cloud));
  icp.setMaxCorrespondenceDistance(params.icp_max_correspondence_m);
  icp.setMaximumIterations(params.icp_iterations);
  icp.setTransformationEpsilon(1e-8);
  icp.setEuclideanFitnessEpsilon(1e-8);
  pcl::PointCloud<pcl::PointNormal> aligned;
  icp.align(aligned, r.T_coarse.matrix().cast<float>());
  r.icp_ms = msSince(t);
  if (!icp.hasConverged()) {
    r.reason = "ICP did not converge";
    return r;
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
    return r;
  }
  r.accepted = true;
  return r;
}

}  // namespace objdb::matching
