#include "core/common/params.h"

#include <algorithm>
#include <cmath>

namespace objdb {
namespace {

Status positive(double v, absl::string_view field) {
  if (std::isfinite(v) && v > 0.0) return absl::OkStatus();
  return absl::InvalidArgumentError(absl::StrFormat("%s must be finite and > 0 (got %g)", field, v));
}

Status inRange(double v, double lo, double hi, absl::string_view field) {
  if (std::isfinite(v) && v >= lo && v <= hi) return absl::OkStatus();
  return absl::InvalidArgumentError(
      absl::StrFormat("%s must be in [%g, %g] (got %g)", field, lo, hi, v));
}

}  // namespace

Status SegmentationParams::validate() const {
  OBJDB_RETURN_IF_ERROR(
      inRange(fill_holes_iterations, 0, 20, "segmentation.fill_holes_iterations"));
  OBJDB_RETURN_IF_ERROR(
      inRange(label_growth_iterations, 0, 50, "segmentation.label_growth_iterations"));
  OBJDB_RETURN_IF_ERROR(inRange(normal_window_px, 3, 51, "segmentation.normal_window_px"));
  if (normal_window_px % 2 == 0) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "segmentation.normal_window_px must be odd (got %d)", normal_window_px));
  }
  OBJDB_RETURN_IF_ERROR(
      positive(normal_max_relative_distance, "segmentation.normal_max_relative_distance"));
  OBJDB_RETURN_IF_ERROR(
      inRange(discontinuity_window_px, 3, 15, "segmentation.discontinuity_window_px"));
  OBJDB_RETURN_IF_ERROR(positive(discontinuity_threshold, "segmentation.discontinuity_threshold"));
  OBJDB_RETURN_IF_ERROR(inRange(convexity_window_px, 3, 15, "segmentation.convexity_window_px"));
  OBJDB_RETURN_IF_ERROR(inRange(convexity_threshold, 0.0, 1.0, "segmentation.convexity_threshold"));
  OBJDB_RETURN_IF_ERROR(inRange(convexity_offset_m, 0.0, 1.0, "segmentation.convexity_offset_m"));
  OBJDB_RETURN_IF_ERROR(
      inRange(convexity_offset_per_m2, 0.0, 0.01, "segmentation.convexity_offset_per_m2"));
  OBJDB_RETURN_IF_ERROR(inRange(min_segment_px, 1, 1 << 24, "segmentation.min_segment_px"));
  return inRange(max_label_growth_distance_m, 0.0, 10.0,
                 "segmentation.max_label_growth_distance_m");
}

Status TsdfParams::validate() const {
  // 1 mm .. 1 m: below, a room needs billions of voxels; above, nothing is an object.
  OBJDB_RETURN_IF_ERROR(inRange(voxel_size_m, 0.001, 1.0, "tsdf.voxel_size_m"));
  OBJDB_RETURN_IF_ERROR(inRange(voxels_per_side, 2, 64, "tsdf.voxels_per_side"));
  OBJDB_RETURN_IF_ERROR(inRange(truncation_voxels, 1.0, 100.0, "tsdf.truncation_voxels"));
  // No depth sensor measures beyond 100 m; longer rays only allocate blocks far away.
  OBJDB_RETURN_IF_ERROR(inRange(max_ray_length_m, 0.01, 100.0, "tsdf.max_ray_length_m"));
  OBJDB_RETURN_IF_ERROR(inRange(min_ray_length_m, 0.0, max_ray_length_m, "tsdf.min_ray_length_m"));
  OBJDB_RETURN_IF_ERROR(inRange(carve_distance_m, 0.0, 2.0, "tsdf.carve_distance_m"));
  OBJDB_RETURN_IF_ERROR(positive(max_weight, "tsdf.max_weight"));
  return inRange(mesh_min_weight, 0.0, max_weight, "tsdf.mesh_min_weight");
}

Status GsmParams::validate() const {
  OBJDB_RETURN_IF_ERROR(inRange(min_label_voxels, 1, 1 << 30, "gsm.min_label_voxels"));
  OBJDB_RETURN_IF_ERROR(inRange(merge_overlap_ratio, 0.0, 1.0, "gsm.merge_overlap_ratio"));
  OBJDB_RETURN_IF_ERROR(
      inRange(association_overlap_ratio, 0.0, 1.0, "gsm.association_overlap_ratio"));
  OBJDB_RETURN_IF_ERROR(inRange(merge_min_frames, 1, 1 << 20, "gsm.merge_min_frames"));
  OBJDB_RETURN_IF_ERROR(inRange(merge_min_joint_share, 0.0, 1.0, "gsm.merge_min_joint_share"));
  OBJDB_RETURN_IF_ERROR(inRange(extraction_age_frames, 1, 1 << 20, "gsm.extraction_age_frames"));
  OBJDB_RETURN_IF_ERROR(inRange(object_gap_m, 0.0, 0.2, "gsm.object_gap_m"));
  OBJDB_RETURN_IF_ERROR(
      inRange(object_min_contact_voxels, 1, 1 << 20, "gsm.object_min_contact_voxels"));
  OBJDB_RETURN_IF_ERROR(
      inRange(object_structure_extent_m, 0.05, 100.0, "gsm.object_structure_extent_m"));
  OBJDB_RETURN_IF_ERROR(inRange(structure_min_span_m, 0.0, 100.0, "gsm.structure_min_span_m"));
  OBJDB_RETURN_IF_ERROR(
      inRange(structure_max_behind_share, 0.0, 1.0, "gsm.structure_max_behind_share"));
  OBJDB_RETURN_IF_ERROR(inRange(structure_normal_deg, 1.0, 89.0, "gsm.structure_normal_deg"));
  OBJDB_RETURN_IF_ERROR(inRange(structure_band_sigmas, 0.5, 20.0, "gsm.structure_band_sigmas"));
  OBJDB_RETURN_IF_ERROR(inRange(object_max_extent_m, 0.1, 1000.0, "gsm.object_max_extent_m"));
  OBJDB_RETURN_IF_ERROR(inRange(object_support_probe_m, 0.0, 5.0, "gsm.object_support_probe_m"));
  OBJDB_RETURN_IF_ERROR(
      inRange(object_support_max_ratio, 0.0, 10.0, "gsm.object_support_max_ratio"));
  OBJDB_RETURN_IF_ERROR(inRange(object_annex_height_m, 0.0, 1.0, "gsm.object_annex_height_m"));
  OBJDB_RETURN_IF_ERROR(inRange(object_shadow_gap_m, 0.0, 2.0, "gsm.object_shadow_gap_m"));
  OBJDB_RETURN_IF_ERROR(
      inRange(structure_update_frames, 1, 1 << 20, "gsm.structure_update_frames"));
  OBJDB_RETURN_IF_ERROR(inRange(object_min_frames, 1, 1 << 20, "gsm.object_min_frames"));
  OBJDB_RETURN_IF_ERROR(inRange(reextract_min_change, 0.0, 1.0, "gsm.reextract_min_change"));
  return inRange(object_update_frames, 1, 1 << 20, "gsm.object_update_frames");
}

Status ModelParams::validate() const {
  OBJDB_RETURN_IF_ERROR(positive(plane_distance_m, "model.plane_distance_m"));
  OBJDB_RETURN_IF_ERROR(inRange(planar_inlier_ratio, 0.0, 1.0, "model.planar_inlier_ratio"));
  OBJDB_RETURN_IF_ERROR(
      inRange(plane_ransac_iterations, 1, 1000000, "model.plane_ransac_iterations"));
  OBJDB_RETURN_IF_ERROR(inRange(plane_noise_sigmas, 0.0, 100.0, "model.plane_noise_sigmas"));
  OBJDB_RETURN_IF_ERROR(inRange(noise_sigma0_m, 0.0, 1.0, "model.noise_sigma0_m"));
  OBJDB_RETURN_IF_ERROR(inRange(noise_sigma2_m, 0.0, 1.0, "model.noise_sigma2_m"));
  OBJDB_RETURN_IF_ERROR(inRange(noise_z0_m, 0.0, 10.0, "model.noise_z0_m"));
  OBJDB_RETURN_IF_ERROR(
      inRange(structure_min_extent_m, 0.0, 100.0, "model.structure_min_extent_m"));
  OBJDB_RETURN_IF_ERROR(inRange(structure_min_share, 0.0, 1.0, "model.structure_min_share"));
  OBJDB_RETURN_IF_ERROR(inRange(structure_max_planes, 0, 10, "model.structure_max_planes"));
  OBJDB_RETURN_IF_ERROR(inRange(min_points, 1, 1 << 30, "model.min_points"));
  return inRange(cloud_spacing_m, 0.0005, 1.0, "model.cloud_spacing_m");
}

float ModelParams::depthNoise(float depth_m) const {
  if (!(std::isfinite(depth_m) && depth_m > 0.0f)) return 0.0f;
  const float dz = depth_m - noise_z0_m;
  return noise_sigma0_m + noise_sigma2_m * dz * dz;
}

float ModelParams::planeDistance(float depth_m) const {
  return std::max(plane_distance_m, plane_noise_sigmas * depthNoise(depth_m));
}

Status KeypointParams::validate() const {
  OBJDB_RETURN_IF_ERROR(positive(harris_radius_m, "keypoints.harris_radius_m"));
  OBJDB_RETURN_IF_ERROR(inRange(harris_min_neighbors, 1, 10000, "keypoints.harris_min_neighbors"));
  OBJDB_RETURN_IF_ERROR(
      inRange(harris_curvature_threshold, 0.0, 1.0, "keypoints.harris_curvature_threshold"));
  OBJDB_RETURN_IF_ERROR(
      inRange(harris_response_threshold, 0.0, 1e6, "keypoints.harris_response_threshold"));
  OBJDB_RETURN_IF_ERROR(positive(iss_border_radius_m, "keypoints.iss_border_radius_m"));
  OBJDB_RETURN_IF_ERROR(positive(iss_salient_radius_m, "keypoints.iss_salient_radius_m"));
  OBJDB_RETURN_IF_ERROR(positive(iss_non_max_radius_m, "keypoints.iss_non_max_radius_m"));
  OBJDB_RETURN_IF_ERROR(inRange(iss_min_neighbors, 1, 10000, "keypoints.iss_min_neighbors"));
  return inRange(uniform_spacing_m, 0.0, 1.0, "keypoints.uniform_spacing_m");
}

Status DescriptorParams::validate() const {
  OBJDB_RETURN_IF_ERROR(inRange(surface_spacing_m, 0.0, 1.0, "descriptors.surface_spacing_m"));
  return positive(fpfh_radius_m, "descriptors.fpfh_radius_m");
}

Status MatchingParams::validate() const {
  OBJDB_RETURN_IF_ERROR(inRange(similarity_threshold, 0.0, 1.0, "matching.similarity_threshold"));
  OBJDB_RETURN_IF_ERROR(inRange(k_nn, 1, 100, "matching.k_nn"));
  OBJDB_RETURN_IF_ERROR(positive(icp_max_rmse_m, "matching.icp_max_rmse_m"));
  OBJDB_RETURN_IF_ERROR(
      positive(ransac_inlier_distance_m, "matching.ransac_inlier_distance_m"));
  OBJDB_RETURN_IF_ERROR(inRange(ransac_iterations, 1, 10000000, "matching.ransac_iterations"));
  OBJDB_RETURN_IF_ERROR(inRange(ransac_min_inliers, 3, 100000, "matching.ransac_min_inliers"));
  OBJDB_RETURN_IF_ERROR(
      positive(icp_max_correspondence_m, "matching.icp_max_correspondence_m"));
  OBJDB_RETURN_IF_ERROR(inRange(coarse_min_agreement, -1.0, 1.0, "matching.coarse_min_agreement"));
  OBJDB_RETURN_IF_ERROR(
      inRange(icp_max_source_points, 10, 10000000, "matching.icp_max_source_points"));
  return inRange(icp_iterations, 1, 10000, "matching.icp_iterations");
}

double MergingParams::minOverlapVoxels(double voxel_size_m) const {
  const double ratio = double(reference_voxel_size_m) / voxel_size_m;
  return double(tsdf_min_overlap_voxels) * ratio * ratio;
}

Status MergingParams::validate() const {
  OBJDB_RETURN_IF_ERROR(positive(tsdf_max_rmse_m, "merging.tsdf_max_rmse_m"));
  OBJDB_RETURN_IF_ERROR(
      inRange(tsdf_min_overlap_voxels, 0.0, 1e9, "merging.tsdf_min_overlap_voxels"));
  OBJDB_RETURN_IF_ERROR(
      inRange(completion_margin_voxels, 0, 4, "merging.completion_margin_voxels"));
  OBJDB_RETURN_IF_ERROR(inRange(colour_max_distance, 0.0, 1.0, "merging.colour_max_distance"));
  OBJDB_RETURN_IF_ERROR(inRange(colour_min_pairs, 1, 1e9, "merging.colour_min_pairs"));
  OBJDB_RETURN_IF_ERROR(inRange(noise_sigmas, 0.0, 10.0, "merging.noise_sigmas"));
  return positive(reference_voxel_size_m, "merging.reference_voxel_size_m");
}

Status DatabaseParams::validate() const {
  OBJDB_RETURN_IF_ERROR(
      inRange(prefilter_neighbours, 1, 10000, "database.prefilter_neighbours"));
  OBJDB_RETURN_IF_ERROR(inRange(prefilter_min_votes, 1, 100000, "database.prefilter_min_votes"));
  OBJDB_RETURN_IF_ERROR(inRange(prefilter_epsilon, 0.0, 100.0, "database.prefilter_epsilon"));
  OBJDB_RETURN_IF_ERROR(inRange(shortlist, 0, 1000000, "database.shortlist"));
  OBJDB_RETURN_IF_ERROR(inRange(max_candidates, 1, 100000, "database.max_candidates"));
  OBJDB_RETURN_IF_ERROR(inRange(stop_after_accepted, 0, 100000, "database.stop_after_accepted"));
  return inRange(threads, 1, 256, "database.threads");
}

Status Params::validate() const {
  OBJDB_RETURN_IF_ERROR(segmentation.validate());
  OBJDB_RETURN_IF_ERROR(tsdf.validate());
  OBJDB_RETURN_IF_ERROR(gsm.validate());
  OBJDB_RETURN_IF_ERROR(model.validate());
  OBJDB_RETURN_IF_ERROR(keypoints.validate());
  OBJDB_RETURN_IF_ERROR(descriptors.validate());
  OBJDB_RETURN_IF_ERROR(matching.validate());
  OBJDB_RETURN_IF_ERROR(merging.validate());
  return database.validate();
}

}  // namespace objdb
