// Surface extraction from the TSDF (the zero level set) as a triangle mesh: marching tetrahedra
// on the grid of voxel centres, each cell split into six tetrahedra around its main diagonal
// (Kuhn triangulation, consistent across neighbouring cells, so the mesh is watertight where the
// surface was observed). Chosen over marching cubes' case tables: no ambiguous cases, no tables,
// the same zero crossings on the grid edges. Incremental: blocks are (re)meshed when integration
// marked them updated; vertices are shared within and across blocks.
#pragma once

#include <map>

#include "absl/container/flat_hash_map.h"
#include "core/common/mesh.h"
#include "core/tsdf/tsdf_layer.h"

namespace objdb::tsdf {

// Triangles of the cells whose lowest corner lies in block `index` (cells reaching into the next
// blocks read their voxels). Cells with a corner lighter than `min_weight` are skipped. Vertex
// colours are interpolated; normals are not set.
TriangleMesh meshBlock(const TsdfLayer& layer, const BlockIndex& index, float min_weight);

// The whole surface of `layer` at once (a MeshLayer over a copy: the layer's update marks stay).
TriangleMesh extractMesh(const TsdfLayer& layer, float min_weight);

// Per-block meshes kept up to date incrementally.
class MeshLayer {
 public:
  explicit MeshLayer(float min_weight) : min_weight_(min_weight) {}
  // Re-meshes the blocks marked updated (and clears the marks), or every block when `all`.
  // A block also re-meshes its lower neighbours, whose cells read its voxels. Returns the number
  // of blocks meshed.
  size_t update(TsdfLayer* layer, bool all = false);
  // The whole surface: block meshes joined, shared vertices merged, area-weighted normals.
  TriangleMesh mesh() const;
  size_t numBlocks() const { return meshes_.size(); }

 private:
  float min_weight_;
  absl::flat_hash_map<BlockIndex, TriangleMesh, BlockIndexHash> meshes_;
};

}  // namespace objdb::tsdf
