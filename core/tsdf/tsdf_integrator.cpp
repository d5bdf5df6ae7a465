#include "core/tsdf/tsdf_integrator.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <thread>
#include <tuple>

#include "absl/container/flat_hash_set.h"

namespace objdb::tsdf {

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

  // 1. Blocks within the truncation band of the measured points, bundled per block. Allocation
  // looks at every other pixel in both directions: at the longest ray (3.5 m at VGA) neighbouring
  // samples are ~1.3 cm apart, far below a block (16 cm), so no block of the band is missed except
  // slivers thinner than that spacing. Along each ray the band is sampled every voxel. The rows
  // are split over the threads, each with its own set; the sets are merged in thread order.
  const Eigen::Vector3f origin = T_wc.translation();
  const float step = layer->voxelSize();
  const float carve = params_.carve_distance_m;
  const float carve_step = 0.5f * layer->voxelSize() * float(layer->voxelsPerSide());
  struct RowsResult {
    absl::flat_hash_set<BlockIndex, BlockIndexHash> touched;
    size_t invalid = 0, out_of_range = 0, used = 0;
  };
  auto touch_rows = [&](int v_begin, int v_end, RowsResult* out) {
    BlockIndex last(INT32_MIN, INT32_MIN, INT32_MIN);
    auto touch = [&](const BlockIndex& b) {
      if (b != last) {
        out->touched.insert(b);
        last = b;
      }
    };
    for (int v = v_begin; v < v_end; ++v) {
      for (int u = 0; u < w; ++u) {
        const float z = depth.data[size_t(v) * w + u];
        if (!isValidDepth(z)) {
          ++out->invalid;
          continue;
        }
        if (!(z >= params_.min_ray_length_m && z <= params_.max_ray_length_m)) {
          ++out->out_of_range;
          continue;
        }
        ++out->used;
        if ((u | v) & 1) continue;
        const Eigen::Vector3f p =
            T_wc * Eigen::Vector3f((float(u) - cx) * z / fx, (float(v) - cy) * z / fy, z);
        const Eigen::Vector3f ray = (p - origin).normalized();
        for (float s = -trunc; s <= trunc + 1e-6f; s += step) touch(layer->blockIndexOf(p + s * ray));
        // Free space in front of the band (every 4th pixel each way, half-block steps: the
        // samples of neighbouring rays are far closer than a block).
        if (carve > 0.0f && ((u | v) & 3) == 0) {
          const float reach =
              std::min(trunc + carve, (p - origin).norm() - params_.min_ray_length_m);
          const int samples = int(std::ceil(carve / carve_step));
          for (int k = 1; k <= samples; ++k) {
            const float s = trunc + std::min(float(k) * carve_step, carve);
            if (s > reach) break;
            touch(layer->blockIndexOf(p - s * ray));
          }
        }
      }
    }
  };
  const size_t row_threads = std::min<size_t>(size_t(threads_), size_t(h));
  std::vector<RowsResult> rows(row_threads);
  {
    // The sampling above looks at absolute rows: the same samples for any thread count.
    auto row_of = [&](size_t t) { return int(size_t(h) * t / row_threads); };
    std::vector<std::thread> workers;
    for (size_t t = 1; t < row_threads; ++t) {
      workers.emplace_back(touch_rows, row_of(t), row_of(t + 1), &rows[t]);
    }
    touch_rows(row_of(0), row_of(1), &rows[0]);  // this thread works too
    for (auto& worker : workers) worker.join();
  }
  absl::flat_hash_set<BlockIndex, BlockIndexHash>& touched = rows[0].touched;
  for (size_t t = 0; t < row_threads; ++t) {
    stats.invalid_depth += rows[t].invalid;
    stats.out_of_range += rows[t].out_of_range;
    stats.points_used += rows[t].used;
    if (t > 0) touched.insert(rows[t].touched.begin(), rows[t].touched.end());
  }
  // Allocated in index order: the layer's state does not depend on the thread count.
  std::vector<BlockIndex> indices(touched.begin(), touched.end());
  std::sort(indices.begin(), indices.end(), [](const BlockIndex& a, const BlockIndex& b) {
    return std::tie(a.z(), a.y(), a.x()) < std::tie(b.z(), b.y(), b.x());
  });
  std::vector<TsdfBlock*> blocks;
  blocks.reserve(indices.size());
  for (const BlockIndex& b : indices) blocks.push_back(&layer->allocateBlock(b));
  stats.blocks_touched = blocks.size();

  // 2. Every voxel of those blocks: project, compare with the measured depth, fuse.
  const Eigen::Isometry3f T_cw = T_wc.inverse();
  const int vps = layer->voxelsPerSide();
  const float voxel = layer->voxelSize();
  const float dropoff_start = -voxel;
  // Blocks are handed out in small chunks from a shared counter: blocks differ in cost (a
  // surface block against one carved in free space), so fixed halves leave a thread idle.
  constexpr size_t kChunk = 8;
  std::atomic<size_t> next_block{0};
  auto integrate_blocks = [&](size_t* updated) {
    size_t n = 0;
    for (size_t first = next_block.fetch_add(kChunk); first < blocks.size();
         first = next_block.fetch_add(kChunk)) {
      const size_t last_block = std::min(blocks.size(), first + kChunk);
      for (size_t k = first; k < last_block; ++k) {
        TsdfBlock& block = *blocks[k];
        const Eigen::Vector3i base = indices[k] * vps;
        bool any = false;
        // Voxel centres in the camera frame, stepped along x: one add per voxel.
        const Eigen::Vector3f step_x = T_cw.linear() * Eigen::Vector3f(voxel, 0.0f, 0.0f);
        for (int z = 0; z < vps; ++z) {
          for (int y = 0; y < vps; ++y) {
            Eigen::Vector3f c = T_cw * layer->voxelCenter(base + Eigen::Vector3i(0, y, z)) - step_x;
            for (int x = 0; x < vps; ++x) {
              c += step_x;
              if (!(c.z() > 0.0f)) continue;
              // Nearest pixel: the range test on the shifted coordinate first, then truncation
              // (cheaper than lround, and NaN fails the test).
              const float fu = fx * c.x() / c.z() + cx + 0.5f;
              const float fv = fy * c.y() / c.z() + cy + 0.5f;
              if (!(fu >= 0.0f && fv >= 0.0f && fu < float(w) && fv < float(h))) continue;
              const int u = int(fu), v = int(fv);
              const float d = depth.data[size_t(v) * w + u];
              if (!(isValidDepth(d) && d >= params_.min_ray_length_m && d <= params_.max_ray_length_m)) {
                continue;
              }
              const float sdf = d - c.z();
              if (sdf < -trunc) continue;  // hidden behind the surface: unobserved
              float weight = 1.0f;
              if (sdf < dropoff_start) weight *= (trunc + sdf) / (trunc + dropoff_start);
              if (!(weight > 0.0f)) continue;
              const float clamped = std::min(sdf, trunc);
              TsdfVoxel& vox = block.voxel(size_t(x) + size_t(vps) * (size_t(y) + size_t(vps) * size_t(z)));
              const float total = vox.weight + weight;
              vox.distance = (vox.distance * vox.weight + clamped * weight) / total;
              if (color) {
                const Rgb8 m = color->data[size_t(v) * w + u];
                auto blend = [&](uint8_t old, uint8_t now) {
                  // Non-negative: + 0.5 and truncation round to nearest (lround is a libm call).
                  return uint8_t((float(old) * vox.weight + float(now) * weight) / total + 0.5f);
                };
                vox.color = Rgb8{blend(vox.color.r, m.r), blend(vox.color.g, m.g), blend(vox.color.b, m.b)};
              }
              vox.weight = std::min(total, params_.max_weight);
              any = true;
              ++n;
            }
          }
        }
        if (any) block.updated = true;
      }
    }
    *updated = n;
  };
  const size_t n_threads = std::min<size_t>(size_t(threads_), std::max<size_t>(1, blocks.size()));
  std::vector<size_t> updated(n_threads, 0);
  if (n_threads == 1) {
    integrate_blocks(&updated[0]);
  } else {
    std::vector<std::thread> workers;
    for (size_t t = 1; t < n_threads; ++t) workers.emplace_back(integrate_blocks, &updated[t]);
    integrate_blocks(&updated[0]);  // this thread works too
    for (auto& worker : workers) worker.join();
  }
  for (size_t n : updated) stats.voxels_updated += n;
  stats.milliseconds =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  return stats;
}

}  // namespace objdb::tsdf
