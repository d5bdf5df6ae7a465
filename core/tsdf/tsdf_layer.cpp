#include "core/tsdf/tsdf_layer.h"

#include <algorithm>
#include <atomic>
#include <cmath>

namespace objdb::tsdf {
namespace {
int floorDiv(int a, int b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }
}  // namespace

StatusOr<TsdfLayer> TsdfLayer::create(float voxel_size, int voxels_per_side) {
  if (!(std::isfinite(voxel_size) && voxel_size >= 0.001f && voxel_size <= 1.0f)) {
    return absl::InvalidArgumentError(
        absl::StrFormat("TSDF voxel size must be in [0.001, 1] m (got %g)", voxel_size));
  }
  if (!(voxels_per_side >= 2 && voxels_per_side <= 64)) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "TSDF voxels per block side must be in [2, 64] (got %d)", voxels_per_side));
  }
  return TsdfLayer(voxel_size, voxels_per_side);
}

TsdfLayer::TsdfLayer(float voxel_size, int voxels_per_side)
    : voxel_size_(voxel_size),
      vps_(voxels_per_side),
      block_size_(voxel_size * float(voxels_per_side)),
      inv_voxel_size_(1.0f / voxel_size),
      inv_block_size_(1.0f / (voxel_size * float(voxels_per_side))) {}

BlockIndex TsdfLayer::blockOfVoxel(const VoxelIndex& v) const {
  return {floorDiv(v.x(), vps_), floorDiv(v.y(), vps_), floorDiv(v.z(), vps_)};
}

size_t TsdfLayer::linearInBlock(const VoxelIndex& v) const {
  const BlockIndex b = blockOfVoxel(v);
  const Eigen::Vector3i local = v - b * vps_;
  return size_t(local.x()) + size_t(vps_) * (size_t(local.y()) + size_t(vps_) * size_t(local.z()));
}

TsdfBlock* TsdfLayer::unshare(std::shared_ptr<TsdfBlock>* slot) {
  if (slot->use_count() > 1) {
    *slot = std::make_shared<TsdfBlock>(**slot);
  } else {
    // The last snapshot sharing this block may just have been released on another thread: its
    // reads happen before these writes (the release in shared_ptr's count decrement).
    std::atomic_thread_fence(std::memory_order_acquire);
  }
  return slot->get();
}

TsdfBlock* TsdfLayer::block(const BlockIndex& b) {
  const auto it = blocks_.find(b);
  return it == blocks_.end() ? nullptr : unshare(&it->second);
}

const TsdfBlock* TsdfLayer::block(const BlockIndex& b) const {
  const auto it = blocks_.find(b);
  return it == blocks_.end() ? nullptr : it->second.get();
}

TsdfBlock& TsdfLayer::allocateBlock(const BlockIndex& b) {
  auto& slot = blocks_[b];
  if (!slot) {
    slot = std::make_shared<TsdfBlock>(vps_);
    return *slot;
  }
  return *unshare(&slot);
}

std::vector<TsdfBlock*> TsdfLayer::allocateBlocks(const std::vector<BlockIndex>& indices,
                                                  WorkerPool* pool) {
  // Room for every index first: the inserts below then never rehash, so the slots' addresses
  // stay valid and each slot is written by one thread only.
  blocks_.reserve(blocks_.size() + indices.size());
  std::vector<TsdfBlock*> out(indices.size(), nullptr);
  std::vector<std::shared_ptr<TsdfBlock>*> pending;  // new, or shared with a snapshot
  std::vector<size_t> pending_at;
  for (size_t k = 0; k < indices.size(); ++k) {
    std::shared_ptr<TsdfBlock>& slot = blocks_.try_emplace(indices[k]).first->second;
    if (slot && slot.use_count() == 1) {
      out[k] = unshare(&slot);  // its own block: no copy
    } else {
      pending.push_back(&slot);
      pending_at.push_back(k);
    }
  }
  auto fill = [&](size_t begin, size_t end) {
    for (size_t i = begin; i < end; ++i) {
      std::shared_ptr<TsdfBlock>& slot = *pending[i];
      if (!slot) slot = std::make_shared<TsdfBlock>(vps_);
      out[pending_at[i]] = unshare(&slot);
    }
  };
  // Threads only for enough memory to be worth one (a block is a few kB to a few hundred kB).
  const int n = int(std::clamp<size_t>(pending.size() / 32, 1, size_t(pool ? pool->threads() : 1)));
  runOnPool(pool, n, [&](int t) {
    fill(pending.size() * size_t(t) / size_t(n), pending.size() * size_t(t + 1) / size_t(n));
  });
  return out;
}

const TsdfVoxel* TsdfLayer::voxel(const VoxelIndex& v) const {
  const TsdfBlock* b = block(blockOfVoxel(v));
  return b ? &b->voxel(linearInBlock(v)) : nullptr;
}

TsdfVoxel* TsdfLayer::voxel(const VoxelIndex& v) {
  TsdfBlock* b = block(blockOfVoxel(v));
  return b ? &b->voxel(linearInBlock(v)) : nullptr;
}

bool TsdfLayer::interpolateDistance(const Eigen::Vector3f& p, float* distance) const {
  float weight;
  return interpolate(p, distance, &weight);
}

bool TsdfLayer::interpolate(const Eigen::Vector3f& p, float* distance, float* weight) const {
  // Voxel centres sit at (i + 0.5) · voxel_size: shift so the lower corner index is floor().
  Eigen::Vector3f q = p * inv_voxel_size_ - Eigen::Vector3f::Constant(0.5f);
  // Within float rounding of a lattice plane, sit on it (a voxel centre mapped through an
  // identity transform must read that voxel alone).
  for (int k = 0; k < 3; ++k) {
    const float r = std::round(q[k]);
    if (std::abs(q[k] - r) < 1e-4f) q[k] = r;
  }
  const Eigen::Vector3f lower = q.array().floor();
  const Eigen::Vector3f f = q - lower;
  const VoxelIndex base = lower.cast<int>();
  float d = 0.0f, w = 0.0f;
  // The common case: all 8 corners in one block, looked up once (else each corner's own).
  const BlockIndex b = blockOfVoxel(base);
  const Eigen::Vector3i local = base - b * vps_;
  const bool one_block = local.x() < vps_ - 1 && local.y() < vps_ - 1 && local.z() < vps_ - 1;
  const TsdfBlock* in = one_block ? block(b) : nullptr;
  const size_t first =
      size_t(local.x()) + size_t(vps_) * (size_t(local.y()) + size_t(vps_) * size_t(local.z()));
  for (int corner = 0; corner < 8; ++corner) {
    const int ox = corner & 1, oy = (corner >> 1) & 1, oz = (corner >> 2) & 1;
    const float wx = ox ? f.x() : 1.0f - f.x();
    const float wy = oy ? f.y() : 1.0f - f.y();
    const float wz = oz ? f.z() : 1.0f - f.z();
    const float c = wx * wy * wz;
    // A corner that does not contribute need not be observed: at a voxel centre the value is
    // that voxel's, whatever its neighbours.
    if (c == 0.0f) continue;
    const TsdfVoxel* v = nullptr;
    if (!one_block) {
      v = voxel(base + Eigen::Vector3i(ox, oy, oz));
    } else if (in != nullptr) {
      v = &in->voxel(first + size_t(ox) + size_t(vps_) * (size_t(oy) + size_t(vps_) * size_t(oz)));
    }
    if (v == nullptr || !(v->weight > 0.0f)) return false;
    d += c * v->distance;
    w += c * v->weight;
  }
  *distance = d;
  *weight = w;
  return true;
}

TsdfLayer TsdfLayer::clone() const {
  TsdfLayer copy(voxel_size_, vps_);
  copy.blocks_.reserve(blocks_.size());
  for (const auto& [index, block] : blocks_) {
    copy.blocks_.emplace(index, std::make_shared<TsdfBlock>(*block));
  }
  return copy;
}

TsdfLayer TsdfLayer::snapshot() const {
  TsdfLayer copy(voxel_size_, vps_);
  copy.blocks_ = blocks_;
  return copy;
}

size_t TsdfLayer::numSharedBlocks() const {
  size_t n = 0;
  for (const auto& [index, block] : blocks_) n += block.use_count() > 1 ? 1 : 0;
  return n;
}

size_t TsdfLayer::numObservedVoxels() const {
  size_t n = 0;
  for (const auto& [index, block] : blocks_) {
    for (const TsdfVoxel& v : block->voxels()) n += v.weight > 0.0f ? 1 : 0;
  }
  return n;
}

}  // namespace objdb::tsdf
