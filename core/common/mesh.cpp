#include "core/common/mesh.h"

namespace objdb {

void TriangleMesh::append(const TriangleMesh& other) {
  // Nothing to add (a block without surface): the normals and colours so far stay.
  if (other.vertices.empty() && other.triangles.empty()) return;
  const int offset = static_cast<int>(vertices.size());
  const bool keep_normals = normals.size() == vertices.size() && !other.normals.empty();
  const bool keep_colors = colors.size() == vertices.size() && !other.colors.empty();
  const bool was_empty = vertices.empty();
  vertices.insert(vertices.end(), other.vertices.begin(), other.vertices.end());
  if (keep_normals || (was_empty && !other.normals.empty())) {
    normals.insert(normals.end(), other.normals.begin(), other.normals.end());
  } else {
    normals.clear();
  }
  if (keep_colors || (was_empty && !other.colors.empty())) {
    colors.insert(colors.end(), other.colors.begin(), other.colors.end());
  } else {
    colors.clear();
  }
  triangles.reserve(triangles.size() + other.triangles.size());
  for (const auto& t : other.triangles) triangles.push_back(t + Eigen::Vector3i::Constant(offset));
}

void TriangleMesh::transform(const Transform& T) {
  const Eigen::Isometry3f Tf = T.cast<float>();
  for (auto& v : vertices) v = Tf * v;
  for (auto& n : normals) n = Tf.linear() * n;
}

void TriangleMesh::computeVertexNormals() {
  normals.assign(vertices.size(), Eigen::Vector3f::Zero());
  for (const auto& t : triangles) {
    const Eigen::Vector3f n =
        (vertices[t[1]] - vertices[t[0]]).cross(vertices[t[2]] - vertices[t[0]]);
    for (int k = 0; k < 3; ++k) normals[t[k]] += n;
  }
  for (auto& n : normals) {
    const float len = n.norm();
    n = len > 0.0f ? Eigen::Vector3f(n / len) : Eigen::Vector3f::UnitZ();
  }
}

double TriangleMesh::surfaceArea() const {
  double area = 0.0;
  for (const auto& t : triangles) {
    const Eigen::Vector3d a = vertices[t[0]].cast<double>();
    area += 0.5 * (vertices[t[1]].cast<double>() - a).cross(vertices[t[2]].cast<double>() - a).norm();
  }
  return area;
}

double TriangleMesh::signedVolume() const {
  double volume = 0.0;
  for (const auto& t : triangles) {
    volume += vertices[t[0]].cast<double>().dot(
                  vertices[t[1]].cast<double>().cross(vertices[t[2]].cast<double>())) /
              6.0;
  }
  return volume;
}

bool TriangleMesh::bounds(Eigen::Vector3f* min, Eigen::Vector3f* max) const {
  if (vertices.empty()) return false;
  *min = *max = vertices.front();
  for (const auto& v : vertices) {
    *min = min->cwiseMin(v);
    *max = max->cwiseMax(v);
  }
  return true;
}

Status TriangleMesh::validate() const {
  if (!normals.empty() && normals.size() != vertices.size()) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "mesh has %d normals for %d vertices", normals.size(), vertices.size()));
  }
  if (!colors.empty() && colors.size() != vertices.size()) {
    return absl::InvalidArgumentError(
        absl::StrFormat("mesh has %d colours for %d vertices", colors.size(), vertices.size()));
  }
  const int n = static_cast<int>(vertices.size());
  for (size_t i = 0; i < triangles.size(); ++i) {
    const auto& t = triangles[i];
    if (!(t.minCoeff() >= 0 && t.maxCoeff() < n)) {
      return absl::InvalidArgumentError(absl::StrFormat(
          "mesh triangle %d references vertex %d but the mesh has %d vertices", i,
          t.minCoeff() < 0 ? t.minCoeff() : t.maxCoeff(), n));
    }
  }
  for (size_t i = 0; i < vertices.size(); ++i) {
    if (!vertices[i].allFinite()) {
      return absl::InvalidArgumentError(absl::StrFormat("mesh vertex %d is not finite", i));
    }
  }
  return absl::OkStatus();
}

}  // namespace objdb
