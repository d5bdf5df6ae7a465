// Triangle meshes: what the synthetic world renders and what marching cubes will produce.
#pragma once

#include <array>
#include <vector>

#include <Eigen/Core>

#include "core/common/image.h"
#include "core/common/transform.h"

namespace objdb {

struct TriangleMesh {
  std::vector<Eigen::Vector3f> vertices;
  std::vector<Eigen::Vector3f> normals;  // per vertex; empty or vertices.size()
  std::vector<Rgb8> colors;              // per vertex; empty or vertices.size()
  std::vector<Eigen::Vector3i> triangles;

  bool empty() const { return triangles.empty(); }
  // Appends `other` (vertex attributes are kept only if both meshes have them).
  void append(const TriangleMesh& other);
  void transform(const Transform& T);
  // Area-weighted vertex normals from the triangles.
  void computeVertexNormals();
  double surfaceArea() const;
  // Signed volume (divergence theorem); meaningful for closed, outward-oriented meshes.
  double signedVolume() const;
  // Axis-aligned bounds; returns false for a mesh without vertices.
  bool bounds(Eigen::Vector3f* min, Eigen::Vector3f* max) const;
  // Every triangle index within range and every attribute array sized right.
  Status validate() const;
};

// A point cloud with optional normals and colours (PLY writer input).
struct PointCloud {
  std::vector<Eigen::Vector3f> points;
  std::vector<Eigen::Vector3f> normals;  // empty or points.size()
  std::vector<Rgb8> colors;              // empty or points.size()
};

}  // namespace objdb
