#include "core/matching/verification.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "absl/container/flat_hash_set.h"
#include "absl/strings/str_format.h"
#include "core/common/grid_key.h"

namespace objdb::matching {
namespace {

// Calls fn(global voxel index, voxel) for every observed voxel of the layer.
template <typename Fn>
void forEachObserved(const tsdf::TsdfLayer& layer, Fn&& fn) {
  const int vps = layer.voxelsPerSide();
  for (const auto& [index, block] : layer.blocks()) {
    const tsdf::VoxelIndex base = index * vps;
    const auto& voxels = block->voxels();
    for (size_t i = 0; i < voxels.size(); ++i) {
      if (!(voxels[i].weight > 0.0f)) continue;
      const tsdf::VoxelIndex v = base + Eigen::Vector3i(int(i % size_t(vps)),
                                                        int((i / size_t(vps)) % size_t(vps)),
                                                        int(i / size_t(vps * vps)));
      fn(v, voxels[i]);
    }
  }
}

bool coloured(const Rgb8& c) { return int(c.r) + int(c.g) + int(c.b) >= kMinColourSum; }

// An observed voxel within one voxel of the surface, with a colour.
bool colouredSurface(const tsdf::TsdfVoxel& v, float voxel_size) {
  return v.weight > 0.0f && std::abs(v.distance) <= voxel_size && coloured(v.color);
}

// The coloured surface voxel of `layer` nearest to p (in its frame), or null.
const tsdf::TsdfVoxel* colouredSurfaceAt(const tsdf::TsdfLayer& layer, const Eigen::Vector3f& p) {
  const tsdf::TsdfVoxel* v = layer.voxel(layer.voxelIndexOf(p));
  return v != nullptr && colouredSurface(*v, layer.voxelSize()) ? v : nullptr;
}

Rgb8 blendColour(const Rgb8& a, float wa, const Rgb8& b, float wb) {
  const float total = wa + wb;
  auto mix = [&](uint8_t x, uint8_t y) {
    return uint8_t(std::clamp((float(x) * wa + float(y) * wb) / total + 0.5f, 0.0f, 255.0f));
  };
  return Rgb8{mix(a.r, b.r), mix(a.g, b.g), mix(a.b, b.b)};
}

// The middle value (upper median); reorders *values, which must not be empty.
double median(std::vector<double>* values) {
  const auto mid = values->begin() + std::ptrdiff_t(values->size() / 2);
  std::nth_element(values->begin(), mid, values->end());
  return *mid;
}

}  // namespace

double chromaticityDistance(const Rgb8& a, const Rgb8& b) {
  const double sa = double(a.r) + a.g + a.b, sb = double(b.r) + b.g + b.b;
  if (sa <= 0.0 || sb <= 0.0) return 0.0;
  return 0.5 * (std::abs(a.r / sa - b.r / sb) + std::abs(a.g / sa - b.g / sb) +
                std::abs(a.b / sa - b.b / sb));
}

ColourAgreement compareColours(const tsdf::TsdfLayer& fixed, const tsdf::TsdfLayer& moving,
                               const Transform& T_fixed_moving) {
  ColourAgreement agreement;
  const Eigen::Isometry3f T_moving_fixed = T_fixed_moving.inverse().cast<float>();
  const Rgb8 grey{1, 1, 1};
  std::vector<double> distances, chromatic;
  forEachObserved(fixed, [&](const tsdf::VoxelIndex& v, const tsdf::TsdfVoxel& voxel) {
    if (!colouredSurface(voxel, fixed.voxelSize())) return;
    const tsdf::TsdfVoxel* other = colouredSurfaceAt(moving, T_moving_fixed * fixed.voxelCenter(v));
    if (other == nullptr) return;
    const double d = chromaticityDistance(voxel.color, other->color);
    distances.push_back(d);
    if (chromaticityDistance(voxel.color, grey) >= kMinSaturation &&
        chromaticityDistance(other->color, grey) >= kMinSaturation) {
      chromatic.push_back(d);
    }
  });
  agreement.pairs = distances.size();
  agreement.chromatic_pairs = chromatic.size();
  if (distances.empty()) return agreement;
  double sum = 0.0;
  for (double d : distances) sum += d;
  agreement.mean_distance = sum / double(distances.size());
  agreement.median_distance = median(&distances);
  agreement.chromatic_median_distance = chromatic.empty() ? 0.0 : median(&chromatic);
  return agreement;
}

GridAgreement compareGrids(const tsdf::TsdfLayer& fixed, const tsdf::TsdfLayer& moving,
                           const Transform& T_fixed_moving) {
  GridAgreement agreement;
  const Eigen::Isometry3f T_moving_fixed = T_fixed_moving.inverse().cast<float>();
  double sum = 0.0;
  forEachObserved(fixed, [&](const tsdf::VoxelIndex& v, const tsdf::TsdfVoxel& voxel) {
    ++agreement.compared;
    float d = 0.0f;
    if (!moving.interpolateDistance(T_moving_fixed * fixed.voxelCenter(v), &d)) return;
    ++agreement.overlap;
    const double e = double(voxel.distance) - double(d);
    sum += e * e;
  });
  agreement.rmse = agreement.overlap ? std::sqrt(sum / double(agreement.overlap)) : 0.0;
  return agreement;
}

Verdict judge(const GridAgreement& agreement, const MergingParams& params, double voxel_size_m) {
  Verdict verdict;
  verdict.agreement = agreement;
  verdict.min_overlap = params.minOverlapVoxels(voxel_size_m);
  if (double(agreement.overlap) < verdict.min_overlap) {
    verdict.reason = absl::StrFormat("overlap %d voxels < o*_TSDF %.0f", agreement.overlap,
                                     verdict.min_overlap);
  } else if (agreement.rmse > double(params.tsdf_max_rmse_m)) {
    verdict.reason = absl::StrFormat("e_TSDF %.4f m > e*_TSDF %.4f m", agreement.rmse,
                                     params.tsdf_max_rmse_m);
  } else {
    verdict.accepted = true;
  }
  return verdict;
}

size_t mergeGrids(tsdf::TsdfLayer* target, const tsdf::TsdfLayer& source,
                  const Transform& T_target_source, float max_weight,
                  const MergeOptions& options, size_t* written_near_surface) {
  const MergeMode mode = options.mode;
  const std::vector<tsdf::VoxelIndex>* source_region = options.source_region;
  const Eigen::Isometry3f T_source_target = T_target_source.inverse().cast<float>();
  const Eigen::Isometry3f T_ts = T_target_source.cast<float>();
  // Target voxels to write: the observed ones, and those around every observed source voxel.
  std::vector<tsdf::VoxelIndex> candidates;
  absl::flat_hash_set<uint64_t> seen;
  if (mode == MergeMode::kFuse) {
    forEachObserved(*target, [&](const tsdf::VoxelIndex& v, const tsdf::TsdfVoxel&) {
      if (seen.insert(packGridKey(v)).second) candidates.push_back(v);
    });
  }
  const float inv = 1.0f / target->voxelSize();
  auto around = [&](const tsdf::VoxelIndex& v) {
    const Eigen::Vector3f p = T_ts * source.voxelCenter(v);
    const Eigen::Vector3i lower =
        (p * inv - Eigen::Vector3f::Constant(0.5f)).array().floor().cast<int>();
    for (int c = 0; c < 8; ++c) {
      const tsdf::VoxelIndex t = lower + Eigen::Vector3i(c & 1, (c >> 1) & 1, (c >> 2) & 1);
      if (seen.insert(packGridKey(t)).second) candidates.push_back(t);
    }
  };
  if (source_region != nullptr) {
    for (const tsdf::VoxelIndex& v : *source_region) {
      const tsdf::TsdfVoxel* voxel = source.voxel(v);
      if (voxel != nullptr && voxel->weight > 0.0f) around(v);
    }
  } else {
    forEachObserved(source, [&](const tsdf::VoxelIndex& v, const tsdf::TsdfVoxel&) { around(v); });
  }
  // Resample first, write after: the writes must not feed later interpolations of the target.
  struct Write {
    tsdf::VoxelIndex index;
    float distance, weight;
    Rgb8 color;
  };
  std::vector<Write> writes;
  for (const tsdf::VoxelIndex& v : candidates) {
    const tsdf::TsdfVoxel* t = target->voxel(v);
    if (mode == MergeMode::kFillUnobserved && t && t->weight > 0.0f &&
        t->weight >= options.observed_min_weight) {
      continue;
    }
    float ds = 0.0f, ws = 0.0f;
    if (!source.interpolate(T_source_target * target->voxelCenter(v), &ds, &ws)) continue;
    const float wt = t ? t->weight : 0.0f;
    const float dt = t ? t->distance : 0.0f;
    const float w = wt + ws;
    // Colour from the nearest source voxel, fused by the same weights where both have one.
    const Eigen::Vector3f ps = T_source_target * target->voxelCenter(v);
    const tsdf::TsdfVoxel* sv = source.voxel(source.voxelIndexOf(ps));
    const bool source_coloured = sv != nullptr && sv->weight > 0.0f && coloured(sv->color);
    const bool target_coloured = t != nullptr && wt > 0.0f && coloured(t->color);
    Rgb8 color = t ? t->color : Rgb8{};
    if (source_coloured) {
      color = target_coloured ? blendColour(t->color, wt, sv->color, ws) : sv->color;
    }
    writes.push_back({v, (wt * dt + ws * ds) / w, std::min(w, max_weight), color});
  }
  if (written_near_surface) {
    *written_near_surface = 0;
    for (const Write& w : writes) {
      *written_near_surface += std::abs(w.distance) <= target->voxelSize() ? 1 : 0;
    }
  }
  for (const Write& w : writes) {
    target->allocateBlock(target->blockOfVoxel(w.index));
    tsdf::TsdfVoxel* voxel = target->voxel(w.index);
    voxel->distance = w.distance;
    voxel->weight = w.weight;
    voxel->color = w.color;
  }
  return writes.size();
}

}  // namespace objdb::matching
