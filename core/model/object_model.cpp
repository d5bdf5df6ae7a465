#include "core/model/object_model.h"

#include <chrono>
#include <cmath>

#include "absl/container/flat_hash_set.h"
#include "absl/strings/str_format.h"
#include "core/common/grid_key.h"
#include "core/model/features.h"
#include "core/model/structure.h"
#include "core/tsdf/mesh_extraction.h"

namespace objdb::model {

bool samePlace(const std::string& session_a, const Transform& T_world_a,
               const std::string& session_b, const Transform& T_world_b,
               const Eigen::Vector3d& centre) {
  return session_a == session_b && (T_world_a * centre - T_world_b * centre).norm() < kSamePlaceM;
}

Eigen::Vector3d placeCentre(const PointCloud& cloud) {
  if (cloud.points.empty()) return Eigen::Vector3d::Zero();
  Eigen::Vector3f lo = cloud.points.front(), hi = lo;
  for (const auto& p : cloud.points) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  return 0.5 * (lo + hi).cast<double>();
}

size_t countPlaces(const std::vector<std::pair<std::string, Transform>>& poses,
                   const Eigen::Vector3d& centre) {
  size_t places = 0;
  for (size_t i = 0; i < poses.size(); ++i) {
    bool joined = false;
    for (size_t j = 0; j < i && !joined; ++j) {
      joined = samePlace(poses[i].first, poses[i].second, poses[j].first, poses[j].second, centre);
    }
    places += joined ? 0 : 1;
  }
  return places;
}
namespace {

using Clock = std::chrono::steady_clock;
double msSince(Clock::time_point t) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

}  // namespace

bool isMatchable(bool planar_or_structure, size_t num_points, size_t num_keypoints,
                 size_t num_descriptors, const ModelParams& params) {
  return !planar_or_structure && num_points >= size_t(params.min_points) && num_keypoints >= 3 &&
         num_descriptors == num_keypoints;
}

bool ObjectModel::matchable(const ModelParams& params) const {
  return isMatchable(planar || structure, cloud.points.size(), keypoint_indices.size(),
                     descriptors.size(), params);
}

ObjectModel cloneModel(const ObjectModel& model) {
  ObjectModel copy(model.grid.clone());
  copy.id = model.id;
  copy.observations = model.observations;
  copy.surface_voxels = model.surface_voxels;
  copy.cloud = model.cloud;
  copy.keypoint_indices = model.keypoint_indices;
  copy.descriptors = model.descriptors;
  copy.planar = model.planar;
  copy.structure = model.structure;
  copy.plane_inlier_ratio = model.plane_inlier_ratio;
  copy.timings = model.timings;
  return copy;
}

StatusOr<PointCloud> surfaceCloud(const tsdf::TsdfLayer& grid,
                                  const std::vector<tsdf::VoxelIndex>& voxels, float min_weight) {
  if (voxels.empty()) return absl::InvalidArgumentError("surface cloud: the segment has no voxels");
  absl::flat_hash_set<uint64_t> inside;
  absl::flat_hash_set<tsdf::BlockIndex, tsdf::BlockIndexHash> blocks;
  inside.reserve(voxels.size());
  for (const auto& v : voxels) {
    inside.insert(packGridKey(v));
    // Cells whose lowest corner is one voxel below also touch v: mesh those blocks too.
    for (int dz = -1; dz <= 0; ++dz) {
      for (int dy = -1; dy <= 0; ++dy) {
        for (int dx = -1; dx <= 0; ++dx) {
          const tsdf::BlockIndex b = grid.blockOfVoxel(v + Eigen::Vector3i(dx, dy, dz));
          if (grid.block(b) != nullptr) blocks.insert(b);
        }
      }
    }
  }
  TriangleMesh mesh;
  std::vector<tsdf::BlockIndex> ordered(blocks.begin(), blocks.end());
  std::sort(ordered.begin(), ordered.end(), [](const auto& a, const auto& b) {
    return std::tie(a.z(), a.y(), a.x()) < std::tie(b.z(), b.y(), b.x());
  });
  for (const auto& b : ordered) mesh.append(tsdf::meshBlock(grid, b, min_weight));
  // Area-weighted normals need shared vertices: weld the vertices blocks have in common.
  TriangleMesh welded;
  absl::flat_hash_map<std::array<float, 3>, int, absl::Hash<std::array<float, 3>>> seen;
  std::vector<int> remap(mesh.vertices.size());
  const bool coloured = mesh.colors.size() == mesh.vertices.size();
  for (size_t i = 0; i < mesh.vertices.size(); ++i) {
    const Eigen::Vector3f& v = mesh.vertices[i];
    const auto [it, inserted] =
        seen.emplace(std::array<float, 3>{v.x(), v.y(), v.z()}, int(welded.vertices.size()));
    if (inserted) {
      welded.vertices.push_back(v);
      if (coloured) welded.colors.push_back(mesh.colors[i]);  // the grid's, as the mesh has
    }
    remap[i] = it->second;
  }
  for (const auto& t : mesh.triangles) {
    welded.triangles.emplace_back(remap[size_t(t[0])], remap[size_t(t[1])], remap[size_t(t[2])]);
  }
  welded.computeVertexNormals();
  // Keep a vertex when the voxel nearest to it is one of the segment's. Marching tetrahedra puts
  // every vertex on an edge between two voxel centres, nearer the one whose |distance| is smaller,
  // so that voxel (the one whose cube holds the vertex) is the one the surface passes through
  // there. A cell merely touching a segment voxel is not enough: at an object's foot such cells
  // hold the support's surface too (a ring of counter top around a mug; tests/core/model/
  // object_model_test.cpp). A vertex midway on an axis-parallel edge (equal |distance| on both
  // sides, as on an analytic grid) has both voxels as nearest: either being the segment's keeps
  // it. Midway on a diagonal edge, the cube that holds it decides.
  PointCloud cloud;
  const float inv = 1.0f / grid.voxelSize();
  const auto nearestIsInside = [&](const Eigen::Vector3f& p) {
    const Eigen::Vector3f f = p * inv;  // voxel centres at integer + 0.5
    const Eigen::Vector3i holder = f.array().floor().cast<int>();
    if (inside.contains(packGridKey(holder))) return true;
    int tied = -1, ties = 0;
    for (int k = 0; k < 3; ++k) {
      const float from_centre = f[k] - (float(holder[k]) + 0.5f);
      if (std::abs(std::abs(from_centre) - 0.5f) < 1e-3f) tied = k, ++ties;
    }
    if (ties != 1) return false;
    Eigen::Vector3i other = holder;
    other[tied] += f[tied] - float(holder[tied]) < 0.5f ? -1 : 1;  // across the cube's face
    return inside.contains(packGridKey(other));
  };
  for (size_t i = 0; i < welded.vertices.size(); ++i) {
    const Eigen::Vector3f& p = welded.vertices[i];
    if (!nearestIsInside(p)) continue;
    const Eigen::Vector3f& n = welded.normals[i];
    if (!(n.squaredNorm() > 0.5f)) continue;  // isolated vertex without a usable normal
    cloud.points.push_back(p);
    cloud.normals.push_back(n);
    if (coloured) cloud.colors.push_back(welded.colors[i]);
  }
  return cloud;
}

PointCloud resampleCloud(const PointCloud& cloud, float spacing) {
  struct Cell {
    Eigen::Vector3d point = Eigen::Vector3d::Zero();
    Eigen::Vector3d normal = Eigen::Vector3d::Zero();
    Eigen::Vector3d colour = Eigen::Vector3d::Zero();
    int count = 0;
  };
  absl::flat_hash_map<uint64_t, Cell> cells;
  const float inv = 1.0f / spacing;
  const bool with_normals = cloud.normals.size() == cloud.points.size();
  const bool with_colours = !cloud.points.empty() && cloud.colors.size() == cloud.points.size();
  for (size_t i = 0; i < cloud.points.size(); ++i) {
    const Eigen::Vector3i c = (cloud.points[i] * inv).array().floor().cast<int>();
    Cell& cell = cells[packGridKey(c)];
    cell.point += cloud.points[i].cast<double>();
    if (with_normals) cell.normal += cloud.normals[i].cast<double>();
    if (with_colours) {
      cell.colour += Eigen::Vector3d(cloud.colors[i].r, cloud.colors[i].g, cloud.colors[i].b);
    }
    ++cell.count;
  }
  std::vector<std::pair<uint64_t, const Cell*>> ordered;
  ordered.reserve(cells.size());
  for (const auto& [key, cell] : cells) ordered.emplace_back(key, &cell);
  std::sort(ordered.begin(), ordered.end(),
            [](const auto& a, const auto& b) { return a.first < b.first; });
  PointCloud out;
  for (const auto& [key, cell] : ordered) {
    if (with_normals) {
      const double norm = cell->normal.norm();
      if (!(norm > 1e-6 * cell->count)) continue;
      out.normals.push_back((cell->normal / norm).cast<float>());
    }
    out.points.push_back((cell->point / double(cell->count)).cast<float>());
    if (with_colours) {
      const Eigen::Vector3d c = (cell->colour / double(cell->count)).array().round();
      out.colors.push_back(Rgb8{uint8_t(c.x()), uint8_t(c.y()), uint8_t(c.z())});
    }
  }
  return out;
}

StatusOr<SegmentModel> buildSegmentModel(tsdf::TsdfLayer grid,
                                         const std::vector<tsdf::VoxelIndex>& voxels,
                                         const ModelBuildParams& params) {
  OBJDB_RETURN_IF_ERROR(params.model.validate());
  OBJDB_RETURN_IF_ERROR(params.keypoints.validate());
  OBJDB_RETURN_IF_ERROR(params.descriptors.validate());
  ObjectModel model(std::move(grid));
  model.surface_voxels = voxels;
  auto t = Clock::now();
  OBJDB_ASSIGN_OR_RETURN(PointCloud surface,
                         surfaceCloud(model.grid, voxels, params.mesh_min_weight));
  model.cloud = resampleCloud(surface, params.model.cloud_spacing_m);
  model.timings.cloud_ms = msSince(t);
  SegmentModel out;
  if (model.cloud.points.empty()) {
    out.unusable_reason = absl::StrFormat(
        "the segment's %d voxels hold no surface (no zero crossing with weight >= %g)",
        voxels.size(), params.mesh_min_weight);
    return out;
  }
  t = Clock::now();
  const SurfaceClass shape =
      classifySurface(model.cloud, params.observation_depth_m, params.model);
  model.plane_inlier_ratio = shape.plane_inlier_ratio;
  model.plane = shape.plane;
  model.shared_planes = shape.shared_planes;
  model.plane_distance_m = shape.plane_distance_m;
  model.planar = shape.planar;
  model.structure = params.structure.value_or(shape.structure);
  model.timings.planarity_ms = msSince(t);
  if (model.planar || model.structure ||
      model.cloud.points.size() < size_t(params.model.min_points)) {
    out.model = std::move(model);
    return out;
  }
  t = Clock::now();
  model.keypoint_indices = detectKeypoints(model.cloud, params.keypoints, nullptr, params.threads);
  model.timings.keypoints_ms = msSince(t);
  t = Clock::now();
  model.descriptors = computeFpfh(model.cloud, &model.keypoint_indices, params.descriptors, params.threads);
  model.timings.descriptors_ms = msSince(t);
  out.model = std::move(model);
  return out;
}

StatusOr<ObjectModel> buildModel(tsdf::TsdfLayer grid, const std::vector<tsdf::VoxelIndex>& voxels,
                                 const ModelBuildParams& params) {
  OBJDB_ASSIGN_OR_RETURN(SegmentModel built, buildSegmentModel(std::move(grid), voxels, params));
  if (!built.model) {
    return absl::FailedPreconditionError("object model: " + built.unusable_reason);
  }
  return *std::move(built.model);
}

}  // namespace objdb::model
