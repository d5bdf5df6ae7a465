// Sparse TSDF volume (paper §III-B, after voxblox): blocks of voxels_per_side³ voxels in a hash
// map keyed by block index, allocated only where surfaces were seen. A voxel holds a truncated
// signed distance (metres, positive in front of the surface), a fusion weight and a colour.
// Blocks are shared copy-on-write: snapshot() is a read-only view of the layer as it is now that
// costs one pointer per block; the layer copies a shared block the first time it writes to it.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include <Eigen/Core>

#include "absl/container/flat_hash_map.h"
#include "core/common/worker_pool.h"
#include "core/common/image.h"
#include "core/common/status.h"

namespace objdb::tsdf {

using BlockIndex = Eigen::Vector3i;
using VoxelIndex = Eigen::Vector3i;  // global voxel index (block index · vps + local index)

struct TsdfVoxel {
  float distance = 0.0f;  // metres, truncated
  float weight = 0.0f;    // 0 = never observed
  Rgb8 color;
};

struct BlockIndexHash {
  size_t operator()(const BlockIndex& b) const {
    // Large primes (Teschner et al. 2003) mixed into 64 bits.
    return size_t(uint64_t(uint32_t(b.x())) * 73856093ULL ^ uint64_t(uint32_t(b.y())) * 19349669ULL ^
                  uint64_t(uint32_t(b.z())) * 83492791ULL);
  }
};

class TsdfBlock {
 public:
  explicit TsdfBlock(int voxels_per_side)
      : voxels_(size_t(voxels_per_side) * voxels_per_side * voxels_per_side) {}
  TsdfVoxel& voxel(size_t linear) { return voxels_[linear]; }
  const TsdfVoxel& voxel(size_t linear) const { return voxels_[linear]; }
  std::vector<TsdfVoxel>& voxels() { return voxels_; }
  const std::vector<TsdfVoxel>& voxels() const { return voxels_; }
  bool updated = false;  // set by integration; cleared by whoever consumes updates (meshing)

 private:
  std::vector<TsdfVoxel> voxels_;
};

class TsdfLayer {
 public:
  // voxel_size in (0, 1] m, voxels_per_side in [2, 64] (checked by create()).
  static StatusOr<TsdfLayer> create(float voxel_size, int voxels_per_side);

  float voxelSize() const { return voxel_size_; }
  int voxelsPerSide() const { return vps_; }
  float blockSize() const { return block_size_; }
  size_t numBlocks() const { return blocks_.size(); }

  BlockIndex blockIndexOf(const Eigen::Vector3f& p) const {
    return (p * inv_block_size_).array().floor().cast<int>();
  }
  VoxelIndex voxelIndexOf(const Eigen::Vector3f& p) const {
    return (p * inv_voxel_size_).array().floor().cast<int>();
  }
  // Centre of a global voxel index, world frame.
  Eigen::Vector3f voxelCenter(const VoxelIndex& v) const {
    return (v.cast<float>() + Eigen::Vector3f::Constant(0.5f)) * voxel_size_;
  }
  BlockIndex blockOfVoxel(const VoxelIndex& v) const;
  size_t linearInBlock(const VoxelIndex& v) const;

  // Mutable access copies a block shared with a snapshot first (copy-on-write).
  TsdfBlock* block(const BlockIndex& b);
  const TsdfBlock* block(const BlockIndex& b) const;
  TsdfBlock& allocateBlock(const BlockIndex& b);
  // allocateBlock for every index (no duplicates), the blocks in the same order. The map grows on
  // the calling thread; new blocks are created (zeroed) and blocks shared with a snapshot are
  // copied on the pool's threads (null: this thread), so a frame's fresh or just-snapshotted
  // blocks do not cost serial memory traffic.
  std::vector<TsdfBlock*> allocateBlocks(const std::vector<BlockIndex>& indices,
                                         WorkerPool* pool);
  const TsdfVoxel* voxel(const VoxelIndex& v) const;
  TsdfVoxel* voxel(const VoxelIndex& v);

  // Trilinear interpolation of the distance at p from the 8 surrounding voxel centres; false
  // when any of them with a non-zero interpolation weight is unobserved (weight 0) or missing
  // (at a voxel centre only that voxel is needed).
  bool interpolateDistance(const Eigen::Vector3f& p, float* distance) const;
  // The same, with the weight interpolated too.
  bool interpolate(const Eigen::Vector3f& p, float* distance, float* weight) const;

  TsdfLayer(TsdfLayer&&) = default;
  TsdfLayer& operator=(TsdfLayer&&) = default;
  TsdfLayer(const TsdfLayer&) = delete;  // clone() or snapshot(): say which
  TsdfLayer& operator=(const TsdfLayer&) = delete;

  // A deep copy.
  TsdfLayer clone() const;
  // The layer as it is now, sharing its blocks: O(blocks) pointers, no voxel copied. Later writes
  // to either layer copy the block they write first (the mutable accessors below do), so the
  // snapshot never changes. A snapshot may be read on another thread while this layer is written,
  // provided only this layer's owner makes snapshots of it.
  TsdfLayer snapshot() const;
  // Blocks this layer shares with a snapshot (or a snapshot with its layer).
  size_t numSharedBlocks() const;
  // Voxels with weight > 0.
  size_t numObservedVoxels() const;

  using BlockMap = absl::flat_hash_map<BlockIndex, std::shared_ptr<TsdfBlock>, BlockIndexHash>;
  // Read the blocks through this; write through block() / allocateBlock(), which unshare.
  const BlockMap& blocks() const { return blocks_; }
  // Bytes held by allocated blocks (voxels only).
  size_t voxelBytes() const { return blocks_.size() * size_t(vps_) * vps_ * vps_ * sizeof(TsdfVoxel); }

 private:
  TsdfLayer(float voxel_size, int voxels_per_side);
  float voxel_size_;
  int vps_;
  float block_size_;
  float inv_voxel_size_;
  float inv_block_size_;
  // The block behind `slot`, copied first when a snapshot shares it.
  TsdfBlock* unshare(std::shared_ptr<TsdfBlock>* slot);
  BlockMap blocks_;
};

}  // namespace objdb::tsdf
