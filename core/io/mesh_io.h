// Mesh and point-cloud files: PLY (ASCII and binary little/big endian) read and write, OBJ and
// STL (ASCII and binary) read. Errors name the file and the line or element that is wrong.
#pragma once

#include <filesystem>
#include <string>

#include "core/common/mesh.h"

namespace objdb::io {

// Reads a triangle mesh, choosing the format by extension (.ply, .obj, .stl; case-insensitive).
// Polygons with more than three corners are fanned into triangles. Vertex normals/colours are
// kept when the file has them.
StatusOr<TriangleMesh> readMesh(const std::filesystem::path& path);

// Binary little-endian PLY (ASCII when `ascii`), with normals and colours when present.
Status writePlyMesh(const std::filesystem::path& path, const TriangleMesh& mesh,
                    bool ascii = false);
Status writePlyCloud(const std::filesystem::path& path, const PointCloud& cloud,
                     bool ascii = false);
// The same files' bytes (e.g. to serve over HTTP); errors start with `what`.
StatusOr<std::string> plyMeshBytes(const TriangleMesh& mesh, bool ascii = false,
                                   const std::string& what = "cannot encode the mesh as PLY");
StatusOr<std::string> plyCloudBytes(const PointCloud& cloud, bool ascii = false,
                                    const std::string& what = "cannot encode the cloud as PLY");

}  // namespace objdb::io
