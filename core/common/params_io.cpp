#include "core/common/params_io.h"

#include <fstream>
#include <sstream>

#include <nlohmann/json.hpp>

namespace objdb {
namespace {

using nlohmann::json;

// Field table per struct: one place that lists every configurable field by its JSON name.
template <typename Fn>
void forEachField(SegmentationParams& p, Fn&& fn) {
  fn("fill_holes_iterations", p.fill_holes_iterations);
  fn("normal_window_px", p.normal_window_px);
  fn("normal_max_relative_distance", p.normal_max_relative_distance);
  fn("discontinuity_window_px", p.discontinuity_window_px);
  fn("discontinuity_threshold", p.discontinuity_threshold);
  fn("convexity_window_px", p.convexity_window_px);
  fn("convexity_threshold", p.convexity_threshold);
  fn("convexity_offset_m", p.convexity_offset_m);
  fn("convexity_offset_per_m2", p.convexity_offset_per_m2);
  fn("min_segment_px", p.min_segment_px);
  fn("max_label_growth_distance_m", p.max_label_growth_distance_m);
  fn("label_growth_iterations", p.label_growth_iterations);
}
template <typename Fn>
void forEachField(TsdfParams& p, Fn&& fn) {
  fn("voxel_size_m", p.voxel_size_m);
  fn("voxels_per_side", p.voxels_per_side);
  fn("truncation_voxels", p.truncation_voxels);
  fn("max_ray_length_m", p.max_ray_length_m);
  fn("min_ray_length_m", p.min_ray_length_m);
  fn("max_weight", p.max_weight);
  fn("mesh_min_weight", p.mesh_min_weight);
  fn("carve_distance_m", p.carve_distance_m);
}
template <typename Fn>
void forEachField(GsmParams& p, Fn&& fn) {
  fn("min_label_voxels", p.min_label_voxels);
  fn("association_overlap_ratio", p.association_overlap_ratio);
  fn("label_history", p.label_history);
  fn("merge_overlap_ratio", p.merge_overlap_ratio);
  fn("merge_min_frames", p.merge_min_frames);
  fn("merge_min_joint_share", p.merge_min_joint_share);
  fn("extraction_age_frames", p.extraction_age_frames);
  fn("objects", p.objects);
  fn("object_gap_m", p.object_gap_m);
  fn("object_min_contact_voxels", p.object_min_contact_voxels);
  fn("object_structure_extent_m", p.object_structure_extent_m);
  fn("structure_min_span_m", p.structure_min_span_m);
  fn("structure_max_behind_share", p.structure_max_behind_share);
  fn("structure_normal_deg", p.structure_normal_deg);
  fn("structure_band_sigmas", p.structure_band_sigmas);
  fn("object_max_extent_m", p.object_max_extent_m);
  fn("object_support_probe_m", p.object_support_probe_m);
  fn("object_support_max_ratio", p.object_support_max_ratio);
  fn("object_annex_height_m", p.object_annex_height_m);
  fn("object_shadow_gap_m", p.object_shadow_gap_m);
  fn("object_update_frames", p.object_update_frames);
  fn("structure_update_frames", p.structure_update_frames);
  fn("object_min_frames", p.object_min_frames);
  fn("reextract_min_change", p.reextract_min_change);
}
template <typename Fn>
void forEachField(ModelParams& p, Fn&& fn) {
  fn("plane_distance_m", p.plane_distance_m);
  fn("planar_inlier_ratio", p.planar_inlier_ratio);
  fn("plane_ransac_iterations", p.plane_ransac_iterations);
  fn("plane_noise_sigmas", p.plane_noise_sigmas);
  fn("noise_sigma0_m", p.noise_sigma0_m);
  fn("noise_sigma2_m", p.noise_sigma2_m);
  fn("noise_z0_m", p.noise_z0_m);
  fn("structure_min_extent_m", p.structure_min_extent_m);
  fn("structure_min_share", p.structure_min_share);
  fn("structure_max_planes", p.structure_max_planes);
  fn("min_points", p.min_points);
  fn("cloud_spacing_m", p.cloud_spacing_m);
}
template <typename Fn>
void forEachField(KeypointParams& p, Fn&& fn) {
  fn("harris_radius_m", p.harris_radius_m);
  fn("harris_min_neighbors", p.harris_min_neighbors);
  fn("harris_curvature_threshold", p.harris_curvature_threshold);
  fn("harris_response_threshold", p.harris_response_threshold);
  fn("iss_border_radius_m", p.iss_border_radius_m);
  fn("iss_salient_radius_m", p.iss_salient_radius_m);
  fn("iss_non_max_radius_m", p.iss_non_max_radius_m);
  fn("iss_min_neighbors", p.iss_min_neighbors);
  fn("uniform_spacing_m", p.uniform_spacing_m);
}
template <typename Fn>
void forEachField(DescriptorParams& p, Fn&& fn) {
  fn("fpfh_radius_m", p.fpfh_radius_m);
  fn("surface_spacing_m", p.surface_spacing_m);
}
template <typename Fn>
void forEachField(MatchingParams& p, Fn&& fn) {
  fn("similarity_threshold", p.similarity_threshold);
  fn("k_nn", p.k_nn);
  fn("icp_max_rmse_m", p.icp_max_rmse_m);
  fn("ransac_inlier_distance_m", p.ransac_inlier_distance_m);
  fn("ransac_iterations", p.ransac_iterations);
  fn("ransac_min_inliers", p.ransac_min_inliers);
  fn("icp_max_correspondence_m", p.icp_max_correspondence_m);
  fn("icp_iterations", p.icp_iterations);
  fn("coarse_min_agreement", p.coarse_min_agreement);
  fn("icp_max_source_points", p.icp_max_source_points);
}
template <typename Fn>
void forEachField(MergingParams& p, Fn&& fn) {
  fn("tsdf_max_rmse_m", p.tsdf_max_rmse_m);
  fn("tsdf_min_overlap_voxels", p.tsdf_min_overlap_voxels);
  fn("reference_voxel_size_m", p.reference_voxel_size_m);
  fn("completion_margin_voxels", p.completion_margin_voxels);
  fn("colour_max_distance", p.colour_max_distance);
  fn("colour_min_pairs", p.colour_min_pairs);
  fn("noise_sigmas", p.noise_sigmas);
}
template <typename Fn>
void forEachField(DatabaseParams& p, Fn&& fn) {
  fn("prefilter_neighbours", p.prefilter_neighbours);
  fn("prefilter_min_votes", p.prefilter_min_votes);
  fn("prefilter_epsilon", p.prefilter_epsilon);
  fn("shortlist", p.shortlist);
  fn("max_candidates", p.max_candidates);
  fn("stop_after_accepted", p.stop_after_accepted);
  fn("merge_co_accepted", p.merge_co_accepted);
  fn("threads", p.threads);
}
template <typename Fn>
void forEachSection(Params& p, Fn&& fn) {
  fn("segmentation", p.segmentation);
  fn("tsdf", p.tsdf);
  fn("gsm", p.gsm);
  fn("model", p.model);
  fn("keypoints", p.keypoints);
  fn("descriptors", p.descriptors);
  fn("matching", p.matching);
  fn("merging", p.merging);
  fn("database", p.database);
}

template <typename T>
Status readNumber(const json& value, const std::string& key, T* out) {
  if constexpr (std::is_same_v<T, bool>) {
    if (!value.is_boolean()) {
      return absl::InvalidArgumentError(
          absl::StrCat("config key '", key, "' must be true or false (got ", value.dump(), ")"));
    }
    *out = value.get<bool>();
  } else if constexpr (std::is_integral_v<T>) {
    if (!value.is_number_integer()) {
      return absl::InvalidArgumentError(
          absl::StrCat("config key '", key, "' must be an integer (got ", value.dump(), ")"));
    }
    const auto v = value.get<int64_t>();
    if (v < std::numeric_limits<T>::min() || v > std::numeric_limits<T>::max()) {
      return absl::InvalidArgumentError(
          absl::StrCat("config key '", key, "' is out of range (got ", v, ")"));
    }
    *out = static_cast<T>(v);
  } else {
    if (!value.is_number()) {
      return absl::InvalidArgumentError(
          absl::StrCat("config key '", key, "' must be a number (got ", value.dump(), ")"));
    }
    *out = value.get<T>();
  }
  return absl::OkStatus();
}

template <typename Section>
Status applySection(const json& object, const std::string& section, Section* params) {
  if (!object.is_object()) {
    return absl::InvalidArgumentError(
        absl::StrCat("config key '", section, "' must be an object"));
  }
  Status status;
  size_t known = 0;
  forEachField(*params, [&](const char* name, auto& field) {
    const auto it = object.find(name);
    if (it == object.end() || !status.ok()) return;
    ++known;
    status = readNumber(*it, section + "." + name, &field);
  });
  OBJDB_RETURN_IF_ERROR(status);
  if (known != object.size()) {
    for (const auto& item : object.items()) {
      const std::string& key = item.key();  // (a structured binding: clang 14 cannot capture it)
      bool found = false;
      forEachField(*params, [&](const char* name, auto&) { found = found || key == name; });
      if (!found) {
        return absl::InvalidArgumentError(
            absl::StrCat("unknown config key '", section, ".", key, "'"));
      }
    }
  }
  return absl::OkStatus();
}

}  // namespace

Status applyParamsJson(absl::string_view text, Params* params) {
  json root;
  try {
    root = json::parse(text.begin(), text.end());
  } catch (const json::exception& e) {  // parse_error, and out_of_range for numbers like 1E99999
    return absl::InvalidArgumentError(absl::StrCat("config is not valid JSON: ", e.what()));
  }
  if (!root.is_object()) return absl::InvalidArgumentError("config must be a JSON object");
  Params updated = *params;
  for (const auto& item : root.items()) {
    const std::string& key = item.key();
    const json& value = item.value();
    Status status = absl::InvalidArgumentError(absl::StrCat(
        "unknown config section '", key,
        "' (known: segmentation, tsdf, gsm, model, keypoints, descriptors, matching, merging, "
        "database)"));
    forEachSection(updated, [&](const char* name, auto& section) {
      if (key == name) status = applySection(value, key, &section);
    });
    OBJDB_RETURN_IF_ERROR(status);
  }
  OBJDB_RETURN_IF_ERROR(updated.validate());
  *params = updated;
  return absl::OkStatus();
}

StatusOr<Params> loadParamsFile(const std::filesystem::path& path) {
  std::ifstream in(path);
  if (!in) return absl::NotFoundError(absl::StrCat("cannot open config file ", path.string()));
  std::stringstream buffer;
  buffer << in.rdbuf();
  Params params;
  OBJDB_RETURN_IF_ERROR(annotate(applyParamsJson(buffer.str(), &params), path.string()));
  return params;
}

std::string paramsToJson(const Params& params) {
  Params copy = params;
  json root = json::object();
  forEachSection(copy, [&](const char* section, auto& fields) {
    json object = json::object();
    forEachField(fields, [&](const char* name, auto& field) { object[name] = field; });
    root[section] = object;
  });
  return root.dump(2);
}

}  // namespace objdb
