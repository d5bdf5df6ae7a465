#include "core/tsdf/mesh_extraction.h"

#include <array>
#include <cmath>

#include "absl/container/flat_hash_set.h"
#include "core/common/grid_key.h"

namespace objdb::tsdf {
namespace {

// Cell corners (x, y, z offsets) and the six tetrahedra around the diagonal 0–6.
constexpr int kCorner[8][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0},
                               {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};
constexpr int kTetra[6][4] = {{0, 5, 1, 6}, {0, 1, 2, 6}, {0, 2, 3, 6},
                              {0, 3, 7, 6}, {0, 7, 4, 6}, {0, 4, 5, 6}};

struct Corner {
  Eigen::Vector3f position;
  float distance;
  Rgb8 color;
  VoxelIndex index;
};

// Key of a grid edge between two voxel centres, independent of direction.
struct EdgeKey {
  uint64_t a, b;
  bool operator==(const EdgeKey& o) const { return a == o.a && b == o.b; }
};
struct EdgeKeyHash {
  size_t operator()(const EdgeKey& k) const { return size_t(k.a * 0x9e3779b97f4a7c15ULL ^ k.b); }
};
uint64_t pack(const VoxelIndex& v) { return packGridKey(v); }
EdgeKey edgeKey(const VoxelIndex& p, const VoxelIndex& q) {
  const uint64_t a = pack(p), b = pack(q);
  return a < b ? EdgeKey{a, b} : EdgeKey{b, a};
}

class MeshBuilder {
 public:
  explicit MeshBuilder(TriangleMesh* mesh) : mesh_(mesh) {}
  int vertex(const Corner& first, const Corner& second) {
    // Interpolate from the endpoint with the smaller key, so the same grid edge met from another
    // cell or block yields bit-identical coordinates (shared vertices merge exactly).
    const bool swap = pack(first.index) > pack(second.index);
    const Corner& p = swap ? second : first;
    const Corner& q = swap ? first : second;
    const EdgeKey key = edgeKey(p.index, q.index);
    const auto it = vertices_.find(key);
    if (it != vertices_.end()) return it->second;
    const float t = p.distance / (p.distance - q.distance);  // signs differ: denominator ≠ 0
    mesh_->vertices.push_back(p.position + t * (q.position - p.position));
    auto mix = [t](uint8_t a, uint8_t b) { return uint8_t(std::lround(a + t * (float(b) - float(a)))); };
    mesh_->colors.push_back(Rgb8{mix(p.color.r, q.color.r), mix(p.color.g, q.color.g),
                                 mix(p.color.b, q.color.b)});
    const int id = int(mesh_->vertices.size()) - 1;
    vertices_.emplace(key, id);
    return id;
  }
  // Adds a triangle facing `outward` (from the inside corners toward the outside ones).
  void triangle(int a, int b, int c, const Eigen::Vector3f& outward) {
    const auto& v = mesh_->vertices;
    const Eigen::Vector3f n = (v[b] - v[a]).cross(v[c] - v[a]);
    if (n.dot(outward) < 0.0f) std::swap(b, c);
    mesh_->triangles.emplace_back(a, b, c);
  }

 private:
  TriangleMesh* mesh_;
  absl::flat_hash_map<EdgeKey, int, EdgeKeyHash> vertices_;
};

void meshTetrahedron(const std::array<const Corner*, 4>& c, MeshBuilder* builder) {
  int inside[4], outside[4], n_in = 0, n_out = 0;
  for (int i = 0; i < 4; ++i) {
    if (c[i]->distance < 0.0f) {
      inside[n_in++] = i;
    } else {
      outside[n_out++] = i;
    }
  }
  if (n_in == 0 || n_out == 0) return;
  Eigen::Vector3f in_centre = Eigen::Vector3f::Zero(), out_centre = Eigen::Vector3f::Zero();
  for (int i = 0; i < n_in; ++i) in_centre += c[inside[i]]->position / float(n_in);
  for (int i = 0; i < n_out; ++i) out_centre += c[outside[i]]->position / float(n_out);
  const Eigen::Vector3f outward = out_centre - in_centre;
  if (n_in == 1 || n_out == 1) {
    // One corner on its own side: one triangle on the three edges leaving it.
    const int lone = n_in == 1 ? inside[0] : outside[0];
    int others[3], k = 0;
    for (int i = 0; i < 4; ++i) {
      if (i != lone) others[k++] = i;
    }
    builder->triangle(builder->vertex(*c[lone], *c[others[0]]),
                      builder->vertex(*c[lone], *c[others[1]]),
                      builder->vertex(*c[lone], *c[others[2]]), outward);
    return;
  }
  // Two and two: a quad on the four edges between the pairs.
  const Corner& a = *c[inside[0]];
  const Corner& b = *c[inside[1]];
  const Corner& p = *c[outside[0]];
  const Corner& q = *c[outside[1]];
  const int ap = builder->vertex(a, p), aq = builder->vertex(a, q);
  const int bq = builder->vertex(b, q), bp = builder->vertex(b, p);
  builder->triangle(ap, aq, bq, outward);
  builder->triangle(ap, bq, bp, outward);
}

void meshCells(const TsdfLayer& layer, const BlockIndex& index, float min_weight,
               MeshBuilder* builder) {
  const int vps = layer.voxelsPerSide();
  const int side = vps + 1;
  // The block's voxels plus one layer from the upper neighbours, fetched once.
  std::vector<const TsdfVoxel*> grid(size_t(side) * side * side, nullptr);
  const VoxelIndex base = index * vps;
  for (int z = 0; z < side; ++z) {
    for (int y = 0; y < side; ++y) {
      for (int x = 0; x < side; ++x) {
        grid[size_t(x) + size_t(side) * (size_t(y) + size_t(side) * size_t(z))] =
            layer.voxel(base + Eigen::Vector3i(x, y, z));
      }
    }
  }
  std::array<Corner, 8> corners;
  for (int z = 0; z < vps; ++z) {
    for (int y = 0; y < vps; ++y) {
      for (int x = 0; x < vps; ++x) {
        bool usable = true, any_in = false, any_out = false;
        for (int k = 0; k < 8 && usable; ++k) {
          const int cx = x + kCorner[k][0], cy = y + kCorner[k][1], cz = z + kCorner[k][2];
          const TsdfVoxel* v = grid[size_t(cx) + size_t(side) * (size_t(cy) + size_t(side) * size_t(cz))];
          usable = v != nullptr && v->weight >= min_weight && v->weight > 0.0f;
          if (!usable) break;
          const VoxelIndex global = base + Eigen::Vector3i(cx, cy, cz);
          corners[size_t(k)] = Corner{layer.voxelCenter(global), v->distance, v->color, global};
          any_in |= v->distance < 0.0f;
          any_out |= v->distance >= 0.0f;
        }
        if (!usable || !any_in || !any_out) continue;
        for (const auto& t : kTetra) {
          meshTetrahedron({&corners[size_t(t[0])], &corners[size_t(t[1])], &corners[size_t(t[2])],
                           &corners[size_t(t[3])]},
                          builder);
        }
      }
    }
  }
}

}  // namespace

TriangleMesh meshBlock(const TsdfLayer& layer, const BlockIndex& index, float min_weight) {
  TriangleMesh mesh;
  MeshBuilder builder(&mesh);
  meshCells(layer, index, min_weight, &builder);
  return mesh;
}

size_t MeshLayer::update(TsdfLayer* layer, bool all) {
  absl::flat_hash_set<BlockIndex, BlockIndexHash> dirty;
  for (const auto& [index, block] : layer->blocks()) {
    if (!all && !block->updated) continue;
    // Through the mutable accessor: a block shared with a snapshot is copied, not changed.
    if (block->updated) layer->block(index)->updated = false;
    // Cells of the lower neighbours read this block's voxels.
    for (int dz = -1; dz <= 0; ++dz) {
      for (int dy = -1; dy <= 0; ++dy) {
        for (int dx = -1; dx <= 0; ++dx) {
          const BlockIndex b = index + Eigen::Vector3i(dx, dy, dz);
          if (layer->block(b) != nullptr) dirty.insert(b);
        }
      }
    }
  }
  for (const BlockIndex& b : dirty) {
    TriangleMesh mesh = meshBlock(*layer, b, min_weight_);
    if (mesh.empty()) {
      meshes_.erase(b);
    } else {
      meshes_[b] = std::move(mesh);
    }
  }
  return dirty.size();
}

TriangleMesh MeshLayer::mesh() const {
  // Join in a fixed block order (deterministic output), merging vertices that sit on the same
  // point (edges shared by cells of two blocks).
  std::map<std::array<int, 3>, const TriangleMesh*> ordered;
  for (const auto& [index, mesh] : meshes_) ordered[{index.x(), index.y(), index.z()}] = &mesh;
  TriangleMesh out;
  absl::flat_hash_map<std::array<float, 3>, int, absl::Hash<std::array<float, 3>>> seen;
  for (const auto& [key, mesh] : ordered) {
    std::vector<int> remap(mesh->vertices.size());
    for (size_t i = 0; i < mesh->vertices.size(); ++i) {
      const Eigen::Vector3f& v = mesh->vertices[i];
      const auto [it, inserted] = seen.emplace(std::array<float, 3>{v.x(), v.y(), v.z()},
                                               int(out.vertices.size()));
      if (inserted) {
        out.vertices.push_back(v);
        out.colors.push_back(mesh->colors[i]);
      }
      remap[i] = it->second;
    }
    for (const auto& t : mesh->triangles) out.triangles.emplace_back(remap[size_t(t[0])], remap[size_t(t[1])], remap[size_t(t[2])]);
  }
  out.computeVertexNormals();
  return out;
}

TriangleMesh extractMesh(const TsdfLayer& layer, float min_weight) {
  TsdfLayer copy = layer.snapshot();  // update() clears flags: never on the caller's blocks
  MeshLayer mesher(min_weight);
  mesher.update(&copy, true);
  return mesher.mesh();
}

}  // namespace objdb::tsdf
