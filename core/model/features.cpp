// The only translation unit of core/model that includes PCL (its headers are slow to compile).
#include "core/model/features.h"

#include <algorithm>
#include <cmath>
#include <iterator>

#include "absl/container/flat_hash_map.h"
#include "core/common/grid_key.h"

#include <pcl/features/fpfh_omp.h>
#include <pcl/keypoints/harris_3d.h>
#include <pcl/keypoints/iss_3d.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>
#include <pcl/sample_consensus/ransac.h>
#include <pcl/sample_consensus/sac_model_plane.h>
#include <pcl/search/kdtree.h>

namespace objdb::model {
namespace {

pcl::PointCloud<pcl::PointXYZ>::Ptr toPcl(const PointCloud& cloud) {
  auto out = std::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
  out->reserve(cloud.points.size());
  for (const auto& p : cloud.points) out->push_back(pcl::PointXYZ(p.x(), p.y(), p.z()));
  return out;
}

pcl::PointCloud<pcl::Normal>::Ptr toPclNormals(const PointCloud& cloud) {
  auto out = std::make_shared<pcl::PointCloud<pcl::Normal>>();
  out->reserve(cloud.normals.size());
  for (const auto& n : cloud.normals) out->push_back(pcl::Normal(n.x(), n.y(), n.z()));
  return out;
}

// Surface variation λ0 / (λ0 + λ1 + λ2) of a neighbourhood (0 on a plane, 1/3 isotropic).
float surfaceVariation(const pcl::PointCloud<pcl::PointXYZ>& cloud,
                       const std::vector<int>& neighbours) {
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (int i : neighbours) mean += cloud[size_t(i)].getVector3fMap().cast<double>();
  mean /= double(neighbours.size());
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (int i : neighbours) {
    const Eigen::Vector3d d = cloud[size_t(i)].getVector3fMap().cast<double>() - mean;
    cov += d * d.transpose();
  }
  const Eigen::Vector3d ev = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(cov).eigenvalues();
  const double sum = ev.sum();
  return sum > 0.0 ? float(ev(0) / sum) : 0.0f;
}

}  // namespace

PlaneFit fitPlane(const PointCloud& cloud, float distance_m, int iterations) {
  PlaneFit fit;
  const std::vector<PlanePiece> planes = fitPlanes(cloud, distance_m, iterations, 1, 3);
  if (planes.empty()) return fit;
  fit.coefficients = planes.front().coefficients;
  fit.inlier_ratio = float(planes.front().inliers.size()) / float(cloud.points.size());
  return fit;
}

std::vector<PlanePiece> fitPlanes(const PointCloud& cloud, float distance_m, int iterations,
                                  int max_planes, size_t min_inliers) {
  std::vector<PlanePiece> planes;
  if (cloud.points.size() < 3) return planes;
  const auto points = toPcl(cloud);
  std::vector<int> remaining(cloud.points.size());
  for (size_t i = 0; i < remaining.size(); ++i) remaining[i] = int(i);
  min_inliers = std::max<size_t>(min_inliers, 3);
  for (int p = 0; p < max_planes && remaining.size() >= min_inliers; ++p) {
    // random = false: PCL seeds its generator with a constant, so the fit is deterministic.
    auto plane =
        std::make_shared<pcl::SampleConsensusModelPlane<pcl::PointXYZ>>(points, remaining, false);
    pcl::RandomSampleConsensus<pcl::PointXYZ> ransac(plane, double(distance_m));
    ransac.setMaxIterations(iterations);
    if (!ransac.computeModel()) break;
    Eigen::VectorXf coefficients;
    ransac.getModelCoefficients(coefficients);
    if (coefficients.size() != 4) break;
    PlanePiece piece;
    piece.coefficients = coefficients.head<4>();
    const float norm = piece.coefficients.head<3>().norm();
    if (!(norm > 0.0f)) break;
    piece.coefficients /= norm;
    // RANSAC's consensus was counted on its best sample; count on the fitted plane, among the
    // points no earlier plane took.
    std::vector<int> inliers;
    plane->selectWithinDistance(coefficients, double(distance_m), inliers);
    if (inliers.size() < min_inliers) break;
    std::sort(inliers.begin(), inliers.end());
    piece.inliers.assign(inliers.begin(), inliers.end());
    std::vector<int> left;
    left.reserve(remaining.size() - inliers.size());
    std::set_difference(remaining.begin(), remaining.end(), inliers.begin(), inliers.end(),
                        std::back_inserter(left));
    remaining.swap(left);
    planes.push_back(std::move(piece));
  }
  return planes;
}

std::vector<uint32_t> detectKeypoints(const PointCloud& cloud, const KeypointParams& params,
                                      KeypointCounts* counts, int threads) {
  threads = std::max(1, threads);
  std::vector<uint32_t> result;
  if (cloud.points.size() < 3 || cloud.normals.size() != cloud.points.size()) return result;
  const auto points = toPcl(cloud);
  const auto normals = toPclNormals(cloud);
  auto tree = std::make_shared<pcl::search::KdTree<pcl::PointXYZ>>();
  tree->setInputCloud(points);

  // ISS: many keypoints, also in smooth areas (paper §III-C.2).
  pcl::ISSKeypoint3D<pcl::PointXYZ, pcl::PointXYZ, pcl::Normal> iss;
  iss.setInputCloud(points);
  iss.setSearchMethod(tree);
  iss.setSalientRadius(params.iss_salient_radius_m);
  iss.setNonMaxRadius(params.iss_non_max_radius_m);
  iss.setBorderRadius(params.iss_border_radius_m);
  iss.setNormals(normals);
  iss.setMinNeighbors(params.iss_min_neighbors);
  iss.setNumberOfThreads(threads);
  pcl::PointCloud<pcl::PointXYZ> iss_points;
  iss.compute(iss_points);
  std::vector<uint32_t> from_iss;
  for (int i : iss.getKeypointsIndices()->indices) from_iss.push_back(uint32_t(i));

  // Harris3D: fewer, more repeatable keypoints; then the k_min and t_curv filters of table I.
  pcl::HarrisKeypoint3D<pcl::PointXYZ, pcl::PointXYZI, pcl::Normal> harris;
  harris.setInputCloud(points);
  harris.setSearchMethod(tree);
  harris.setNormals(normals);
  harris.setRadius(params.harris_radius_m);
  harris.setThreshold(params.harris_response_threshold);
  harris.setNonMaxSupression(true);
  harris.setRefine(false);  // keypoints stay cloud points (indices)
  harris.setNumberOfThreads(threads);
  pcl::PointCloud<pcl::PointXYZI> harris_points;
  harris.compute(harris_points);
  std::vector<uint32_t> from_harris;
  std::vector<int> neighbours;
  std::vector<float> distances;
  for (int i : harris.getKeypointsIndices()->indices) {
    const int n = tree->radiusSearch((*points)[size_t(i)], params.harris_radius_m, neighbours,
                                     distances);
    if (n < params.harris_min_neighbors) continue;
    if (surfaceVariation(*points, neighbours) < params.harris_curvature_threshold) continue;
    from_harris.push_back(uint32_t(i));
  }

  std::sort(from_iss.begin(), from_iss.end());
  std::sort(from_harris.begin(), from_harris.end());
  std::set_union(from_iss.begin(), from_iss.end(), from_harris.begin(), from_harris.end(),
                 std::back_inserter(result));
  result.erase(std::unique(result.begin(), result.end()), result.end());
  if (counts) {
    counts->iss = from_iss.size();
    counts->harris = from_harris.size();
    counts->both = from_iss.size() + from_harris.size() - result.size();
  }
  if (params.uniform_spacing_m > 0.0f) {
    // The point nearest each cube's centre (ties: the lower index), deterministic.
    const float s = params.uniform_spacing_m;
    absl::flat_hash_map<uint64_t, std::pair<float, uint32_t>> nearest;
    for (uint32_t i = 0; i < cloud.points.size(); ++i) {
      const Eigen::Vector3f q = cloud.points[i] / s;
      const Eigen::Vector3f cell = q.array().floor();
      const float d = (q - cell - Eigen::Vector3f::Constant(0.5f)).squaredNorm();
      const uint64_t key = packGridKey(cell.cast<int>());
      const auto [it, inserted] = nearest.try_emplace(key, d, i);
      if (!inserted && d < it->second.first) it->second = {d, i};
    }
    std::vector<uint32_t> uniform;
    uniform.reserve(nearest.size());
    for (const auto& [key, best] : nearest) uniform.push_back(best.second);
    std::sort(uniform.begin(), uniform.end());
    std::vector<uint32_t> merged;
    std::set_union(result.begin(), result.end(), uniform.begin(), uniform.end(),
                   std::back_inserter(merged));
    if (counts) counts->uniform = merged.size() - result.size();
    result = std::move(merged);
  }
  return result;
}

std::vector<Fpfh> computeFpfh(const PointCloud& cloud, std::vector<uint32_t>* indices,
                              const DescriptorParams& params, int threads) {
  std::vector<Fpfh> result;
  if (indices->empty() || cloud.normals.size() != cloud.points.size()) {
    indices->clear();
    return result;
  }
  auto keypoints = std::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
  for (uint32_t i : *indices) {
    keypoints->push_back(pcl::PointXYZ(cloud.points[i].x(), cloud.points[i].y(), cloud.points[i].z()));
  }
  const PointCloud* surface = &cloud;
  PointCloud resampled;
  if (params.surface_spacing_m > 0.0f) {
    resampled = resampleCloud(cloud, params.surface_spacing_m);
    surface = &resampled;
  }
  const auto points = toPcl(*surface);
  const auto normals = toPclNormals(*surface);
  // The OpenMP variant is precompiled in libpcl_features; with one thread it equals the plain one.
  pcl::FPFHEstimationOMP<pcl::PointXYZ, pcl::Normal, pcl::FPFHSignature33> fpfh(
      static_cast<unsigned int>(std::max(1, threads)));
  fpfh.setSearchSurface(points);
  fpfh.setInputNormals(normals);
  fpfh.setInputCloud(keypoints);
  fpfh.setSearchMethod(std::make_shared<pcl::search::KdTree<pcl::PointXYZ>>());
  fpfh.setRadiusSearch(params.fpfh_radius_m);
  pcl::PointCloud<pcl::FPFHSignature33> descriptors;
  fpfh.compute(descriptors);
  std::vector<uint32_t> kept;
  for (size_t k = 0; k < descriptors.size(); ++k) {
    const float* h = descriptors[k].histogram;
    if (!std::all_of(h, h + 33, [](float v) { return std::isfinite(v); })) continue;
    Fpfh d;
    std::copy(h, h + 33, d.begin());
    result.push_back(d);
    kept.push_back((*indices)[k]);
  }
  *indices = std::move(kept);
  return result;
}

}  // namespace objdb::model
