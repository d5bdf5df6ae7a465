#include "core/tsdf/tsdf_integrator.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>

#include "absl/container/flat_hash_set.h"
#include "core/common/simd.h"

namespace objdb::tsdf {
namespace {

// floor() to int without a libm call (the x86-64 baseline has no SSE4.1 rounding): exact for
// finite |x| < 2³¹, which every point of a validated pose and a depth ≤ 100 m is in block units.
inline int floorToInt(float x) {
  const int i = int(x);
  return i - int(x < float(i));
}

// The blocks one thread's rows touch. A small direct-mapped cache of the latest blocks keeps the
// neighbouring rays, which touch the same few blocks, away from the hash set.
class BlockCollector {
 public:
  BlockCollector() { recent_.fill(BlockIndex(INT32_MIN, INT32_MIN, INT32_MIN)); }
  void add(int x, int y, int z) {
    const BlockIndex b(x, y, z);
    const size_t slot = BlockIndexHash{}(b) & (kSlots - 1);
    if (recent_[slot] == b) return;
    recent_[slot] = b;
    blocks.insert(b);
  }
  absl::flat_hash_set<BlockIndex, BlockIndexHash> blocks;
  size_t invalid = 0, out_of_range = 0, used = 0;

 private:
  static constexpr size_t kSlots = 64;
  std::array<BlockIndex, kSlots> recent_;
};

// Every block the segment a → b (both in block units) passes through, a's first: a 3D DDA
// (Amanatides & Woo) that steps only along axes still short of b's block, so it ends there
// after exactly the Manhattan distance between the two blocks.
void touchSegment(const Eigen::Vector3f& a, const Eigen::Vector3f& b, BlockCollector* out) {
  int at[3] = {floorToInt(a.x()), floorToInt(a.y()), floorToInt(a.z())};
  const int end[3] = {floorToInt(b.x()), floorToInt(b.y()), floorToInt(b.z())};
  out->add(at[0], at[1], at[2]);
  int steps = std::abs(end[0] - at[0]) + std::abs(end[1] - at[1]) + std::abs(end[2] - at[2]);
  if (steps == 0) return;
  const Eigen::Vector3f d = b - a;
  float t_next[3], t_delta[3];
  int dir[3];
  for (int k = 0; k < 3; ++k) {
    dir[k] = end[k] > at[k] ? 1 : (end[k] < at[k] ? -1 : 0);
    if (dir[k] == 0) {
      t_next[k] = t_delta[k] = INFINITY;
      continue;
    }
    const float boundary = float(dir[k] > 0 ? at[k] + 1 : at[k]);
    t_next[k] = (boundary - a[k]) / d[k];
    t_delta[k] = float(dir[k]) / d[k];
  }
  while (steps-- > 0) {
    int k = -1;
    for (int j = 0; j < 3; ++j) {
      if (at[j] != end[j] && (k < 0 || t_next[j] < t_next[k])) k = j;
    }
    at[k] += dir[k];
    t_next[k] += t_delta[k];
    out->add(at[0], at[1], at[2]);
  }
}

// What the voxel pass of one frame reads.
struct VoxelPass {
  const TsdfLayer* layer = nullptr;  // voxel size, block side, voxel centres
  const float* depth = nullptr;
  const Rgb8* color = nullptr;  // or none
  int w = 0, h = 0;
  Eigen::Isometry3f T_cw;       // world → camera
  float fx = 0, fy = 0, cx = 0, cy = 0;
  float trunc = 0, dropoff_start = 0, min_ray = 0, max_ray = 0, max_weight = 0;
};

constexpr int kMaxRow = 64;  // TsdfParams::voxels_per_side ≤ 64

// One row of voxels along x, camera-frame centre c0 and step sx: the projection of every voxel
// in branch-free loops (vectorised), then the update of those with a usable depth in front of
// them. Returns the voxels updated.
OBJDB_INLINE_KERNEL size_t integrateRow(const VoxelPass& p, const Eigen::Vector3f& c0,
                                        const Eigen::Vector3f& sx, TsdfVoxel* row) {
  int pixel[kMaxRow];
  float voxel_z[kMaxRow];
  const int n = p.layer->voxelsPerSide();
  const float w = float(p.w), h = float(p.h);
  for (int x = 0; x < n; ++x) {
    const float fxv = float(x);
    const float X = c0.x() + fxv * sx.x(), Y = c0.y() + fxv * sx.y(), Z = c0.z() + fxv * sx.z();
    // Nearest pixel: the range test on the shifted coordinate, then truncation (NaN and a voxel
    // behind the camera fail it).
    const float inv_z = 1.0f / Z;
    const float fu = p.fx * X * inv_z + p.cx + 0.5f;
    const float fv = p.fy * Y * inv_z + p.cy + 0.5f;
    const bool inside = Z > 0.0f && fu >= 0.0f && fv >= 0.0f && fu < w && fv < h;
    const int u = int(inside ? fu : 0.0f), v = int(inside ? fv : 0.0f);
    pixel[x] = inside ? v * p.w + u : -1;
    voxel_z[x] = Z;
  }
  size_t updated = 0;
  for (int x = 0; x < n; ++x) {
    if (pixel[x] < 0) continue;
    const float d = p.depth[pixel[x]];
    // Valid (finite, > 0) and within the ray limits: NaN and ±inf fail one of the compares.
    if (!(d > 0.0f && d >= p.min_ray && d <= p.max_ray)) continue;
    const float sdf = d - voxel_z[x];
    if (sdf < -p.trunc) continue;  // hidden behind the surface: unobserved
    float weight = 1.0f;
    if (sdf < p.dropoff_start) weight = (p.trunc + sdf) / (p.trunc + p.dropoff_start);
    if (!(weight > 0.0f)) continue;
    const float clamped = std::min(sdf, p.trunc);
    TsdfVoxel& vox = row[x];
    const float total = vox.weight + weight;
    vox.distance = (vox.distance * vox.weight + clamped * weight) / total;
    if (p.color) {
      const Rgb8 m = p.color[pixel[x]];
      auto blend = [&](uint8_t old, uint8_t now) {
        // Non-negative: + 0.5 and truncation round to nearest (lround is a libm call).
        return uint8_t((float(old) * vox.weight + float(now) * weight) / total + 0.5f);
      };
      vox.color = Rgb8{blend(vox.color.r, m.r), blend(vox.color.g, m.g), blend(vox.color.b, m.b)};
    }
    vox.weight = std::min(total, p.max_weight);
    ++updated;
  }
  return updated;
}

// Every voxel of blocks [first, last): project, compare with the measured depth, fuse.
OBJDB_VECTOR_CLONES
size_t integrateBlocks(const VoxelPass& p, TsdfBlock* const* blocks, const BlockIndex* indices,
                       size_t first, size_t last) {
  size_t updated = 0;
  const int vps = p.layer->voxelsPerSide();
  // Voxel centres in the camera frame: a row's first centre, then one step along x per voxel.
  const Eigen::Vector3f sx = p.T_cw.linear() * Eigen::Vector3f(p.layer->voxelSize(), 0.0f, 0.0f);
  for (size_t k = first; k < last; ++k) {
    TsdfBlock& block = *blocks[k];
    const Eigen::Vector3i base = indices[k] * vps;
    size_t in_block = 0;
    for (int z = 0; z < vps; ++z) {
      for (int y = 0; y < vps; ++y) {
        const Eigen::Vector3f centre = p.layer->voxelCenter(base + Eigen::Vector3i(0, y, z));
        in_block += integrateRow(p, p.T_cw * centre, sx,
                                 &block.voxel(size_t(vps) * (size_t(y) + size_t(vps) * size_t(z))));
      }
    }
    if (in_block) block.updated = true;
    updated += in_block;
  }
  return updated;
}

}  // namespace

TsdfIntegrator::TsdfIntegrator(const TsdfParams& params, const Intrinsics& intrinsics, int threads)
    : params_(params),
      intrinsics_(intrinsics),
      threads_(threads),
      pool_(threads > 1 ? std::make_shared<WorkerPool>(threads) : nullptr) {}

StatusOr<TsdfIntegrator> TsdfIntegrator::create(const TsdfParams& params,
                                                const Intrinsics& intrinsics, int threads) {
  OBJDB_RETURN_IF_ERROR(params.validate());
  OBJDB_RETURN_IF_ERROR(intrinsics.validate());
  if (!(threads >= 1 && threads <= 256)) {
    return absl::InvalidArgumentError(absl::StrCat("integrator threads must be in 1..256 (got ", threads, ")"));
  }
  return TsdfIntegrator(params, intrinsics, threads);
}

StatusOr<IntegrationStats> TsdfIntegrator::integrate(const DepthImage& depth,
                                                     const Transform& T_world_camera,
                                                     TsdfLayer* layer,
                                                     const ColorImage* color) const {
  const auto start = std::chrono::steady_clock::now();
  OBJDB_RETURN_IF_ERROR(intrinsics_.checkImageSize(depth.width, depth.height, "depth image"));
  if (depth.data.size() != size_t(depth.width) * size_t(depth.height)) {
    return absl::InvalidArgumentError("depth image has the wrong number of pixels");
  }
  if (color) {
    OBJDB_RETURN_IF_ERROR(intrinsics_.checkImageSize(color->width, color->height, "colour image"));
  }
  OBJDB_RETURN_IF_ERROR(validateTransform(T_world_camera, "camera pose T_world_camera"));
  if (!(std::abs(layer->voxelSize() - params_.voxel_size_m) <= 1e-6f * params_.voxel_size_m &&
        layer->voxelsPerSide() == params_.voxels_per_side)) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "TSDF layer has %g m voxels, %d per block side; the integrator is set up for %g m, %d",
        layer->voxelSize(), layer->voxelsPerSide(), params_.voxel_size_m,
        params_.voxels_per_side));
  }

  IntegrationStats stats;
  const float trunc = params_.truncationDistance();
  const Eigen::Isometry3f T_wc = T_world_camera.cast<float>();
  const float fx = float(intrinsics_.fx), fy = float(intrinsics_.fy);
  const float cx = float(intrinsics_.cx), cy = float(intrinsics_.cy);
  const int w = depth.width, h = depth.height;

  // 1. Blocks within the truncation band of the measured points. Allocation looks at every other
  // pixel in both directions: at the longest ray (3.5 m at VGA) neighbouring samples are ~1.3 cm
  // apart, far below a block (16 cm), so no block of the band is missed except slivers thinner
  // than that spacing. Each ray's band [−truncation, +truncation] around its point is walked
  // block by block; every 4th pixel each way also walks the free space in front of the band up
  // to carve_distance_m (the samples of neighbouring rays are far closer than a block). The rows
  // are shared out between the threads, each with its own set; the sets are merged.
  const Eigen::Vector3f origin = T_wc.translation();
  const float carve = params_.carve_distance_m;
  const float inv_block = 1.0f / (layer->voxelSize() * float(layer->voxelsPerSide()));
  const float min_ray = params_.min_ray_length_m, max_ray = params_.max_ray_length_m;
  auto touch_rows = [&](int v_begin, int v_end, BlockCollector* out) {
    size_t invalid = 0, out_of_range = 0, used = 0;  // local: the collectors share cache lines
    for (int v = v_begin; v < v_end; ++v) {
      const float* row = depth.data.data() + size_t(v) * size_t(w);
      for (int u = 0; u < w; ++u) {
        const float z = row[u];
        if (!isValidDepth(z)) {
          ++invalid;
          continue;
        }
        if (!(z >= min_ray && z <= max_ray)) {
          ++out_of_range;
          continue;
        }
        ++used;
        if ((u | v) & 1) continue;
        const Eigen::Vector3f p =
            T_wc * Eigen::Vector3f((float(u) - cx) * z / fx, (float(v) - cy) * z / fy, z);
        const float range = (p - origin).norm();
        const Eigen::Vector3f ray = (p - origin) / range;
        float front = trunc;  // how far toward the camera the walk goes
        if (carve > 0.0f && ((u | v) & 3) == 0) {
          front = std::max(trunc, std::min(trunc + carve, range - min_ray));
        }
        touchSegment((p + trunc * ray) * inv_block, (p - front * ray) * inv_block, out);
      }
    }
    out->invalid += invalid;
    out->out_of_range += out_of_range;
    out->used += used;
  };
  const size_t row_threads = std::min<size_t>(size_t(threads_), size_t(h));
  std::vector<BlockCollector> rows(row_threads);
  {
    // Rows are handed out in chunks from a shared counter (the floor near the camera costs more
    // than a window); the sampling above looks at absolute rows, so the blocks are the same for
    // any thread count.
    constexpr int kRowChunk = 16;
    std::atomic<int> next_row{0};
    auto collect = [&](BlockCollector* out) {
      for (int v = next_row.fetch_add(kRowChunk); v < h; v = next_row.fetch_add(kRowChunk)) {
        touch_rows(v, std::min(h, v + kRowChunk), out);
      }
    };
    runOnPool(pool_.get(), int(row_threads), [&](int t) { collect(&rows[size_t(t)]); });
  }
  absl::flat_hash_set<BlockIndex, BlockIndexHash>& touched = rows[0].blocks;
  for (size_t t = 0; t < row_threads; ++t) {
    stats.invalid_depth += rows[t].invalid;
    stats.out_of_range += rows[t].out_of_range;
    stats.points_used += rows[t].used;
    if (t > 0) touched.insert(rows[t].blocks.begin(), rows[t].blocks.end());
  }
  // Allocated in index order (z, y, x): the layer's state does not depend on the thread count.
  // Sorted as one 64-bit key each (21 bits per axis, offset to non-negative), which orders them
  // as the index tuples do while |index| < 2²⁰ blocks (≥ 20 km at 2 cm voxels).
  auto key = [](const BlockIndex& b) {
    constexpr int64_t kOffset = int64_t(1) << 20;
    return (uint64_t(b.z() + kOffset) << 42) | (uint64_t(b.y() + kOffset) << 21) |
           uint64_t(b.x() + kOffset);
  };
  std::vector<std::pair<uint64_t, BlockIndex>> keyed;
  keyed.reserve(touched.size());
  for (const BlockIndex& b : touched) keyed.emplace_back(key(b), b);
  std::sort(keyed.begin(), keyed.end(),
            [](const auto& a, const auto& b) { return a.first < b.first; });
  std::vector<BlockIndex> indices;
  indices.reserve(keyed.size());
  for (const auto& [k, b] : keyed) indices.push_back(b);
  const std::vector<TsdfBlock*> blocks = layer->allocateBlocks(indices, pool_.get());
  stats.blocks_touched = blocks.size();

  // 2. Every voxel of those blocks: project, compare with the measured depth, fuse. Blocks are
  // handed out in small chunks from a shared counter: blocks differ in cost (a surface block
  // against one carved in free space), so fixed halves leave a thread idle.
  VoxelPass pass;
  pass.depth = depth.data.data();
  pass.color = color ? color->data.data() : nullptr;
  pass.layer = layer;
  pass.w = w;
  pass.h = h;
  pass.T_cw = T_wc.inverse();
  pass.fx = fx;
  pass.fy = fy;
  pass.cx = cx;
  pass.cy = cy;
  pass.trunc = trunc;
  pass.dropoff_start = -layer->voxelSize();
  pass.min_ray = min_ray;
  pass.max_ray = max_ray;
  pass.max_weight = params_.max_weight;
  constexpr size_t kChunk = 8;
  std::atomic<size_t> next_block{0};
  auto integrate_chunks = [&](size_t* updated) {
    size_t n = 0;
    for (size_t first = next_block.fetch_add(kChunk); first < blocks.size();
         first = next_block.fetch_add(kChunk)) {
      n += integrateBlocks(pass, blocks.data(), indices.data(), first,
                           std::min(blocks.size(), first + kChunk));
    }
    *updated = n;
  };
  const size_t n_threads = std::min<size_t>(size_t(threads_), std::max<size_t>(1, blocks.size()));
  std::vector<size_t> updated(n_threads, 0);
  runOnPool(pool_.get(), int(n_threads), [&](int t) { integrate_chunks(&updated[size_t(t)]); });
  for (size_t n : updated) stats.voxels_updated += n;
  stats.milliseconds =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  return stats;
}

}  // namespace objdb::tsdf
