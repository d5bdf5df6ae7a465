#include "core/gsm/gsm.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <tuple>

namespace objdb::gsm {
namespace {

uint64_t packVoxel(const tsdf::VoxelIndex& v) {
  auto f = [](int c) { return uint64_t(uint32_t(c + (1 << 20)) & 0x1fffff); };
  return f(v.x()) | (f(v.y()) << 21) | (f(v.z()) << 42);
}
tsdf::VoxelIndex unpackVoxel(uint64_t k) {
  auto g = [](uint64_t bits) { return int(bits & 0x1fffff) - (1 << 20); };
  return {g(k), g(k >> 21), g(k >> 42)};
}
uint64_t packPair(Label a, Label b) {
  return a < b ? (uint64_t(a) << 32) | b : (uint64_t(b) << 32) | a;
}

// Up to two segments' votes for one voxel within a frame (the voxel votes once, for the larger).
struct FrameVotes {
  int32_t segment[2] = {0, 0};
  uint32_t count[2] = {0, 0};
  void add(int32_t s) {
    for (int i = 0; i < 2; ++i) {
      if (segment[i] == s || segment[i] == 0) {
        segment[i] = s;
        ++count[i];
        return;
      }
    }
    // A third segment: replace the weaker one (space-saving, as in the label voxels).
    const int weak = count[0] <= count[1] ? 0 : 1;
    segment[weak] = s;
    ++count[weak];
  }
  int32_t winner() const { return count[0] >= count[1] ? segment[0] : segment[1]; }
};

}  // namespace

StatusOr<Gsm> Gsm::create(const TsdfParams& tsdf_params, const GsmParams& gsm_params,
                          const Intrinsics& intrinsics, int threads) {
  OBJDB_RETURN_IF_ERROR(gsm_params.validate());
  OBJDB_ASSIGN_OR_RETURN(tsdf::TsdfIntegrator integrator,
                         tsdf::TsdfIntegrator::create(tsdf_params, intrinsics, threads));
  OBJDB_ASSIGN_OR_RETURN(tsdf::TsdfLayer layer, tsdf::TsdfLayer::create(
                                                    tsdf_params.voxel_size_m,
                                                    tsdf_params.voxels_per_side));
  Gsm gsm(tsdf_params, gsm_params, std::move(integrator), std::move(layer));
  gsm.intrinsics_ = intrinsics;
  return gsm;
}

Gsm::Gsm(const TsdfParams& tsdf_params, const GsmParams& gsm_params,
         tsdf::TsdfIntegrator integrator, tsdf::TsdfLayer layer)
    : tsdf_params_(tsdf_params),
      params_(gsm_params),
      integrator_(std::move(integrator)),
      layer_(std::move(layer)) {}

Label Gsm::resolve(Label label) const {
  auto it = parent_.find(label);
  while (it != parent_.end() && it->second != label) {
    label = it->second;
    it = parent_.find(label);
  }
  return label;
}

Label Gsm::mainOf(const LabelVoxel& voxel) const {
  // Merged labels pool their votes: the main label is the root with the most.
  Label roots[kLabelSlots] = {};
  uint32_t sums[kLabelSlots] = {};
  for (int i = 0; i < kLabelSlots; ++i) {
    if (voxel.labels[size_t(i)] == 0) continue;
    const Label r = resolve(voxel.labels[size_t(i)]);
    for (int j = 0; j < kLabelSlots; ++j) {
      if (roots[j] == r || roots[j] == 0) {
        roots[j] = r;
        sums[j] += voxel.counts[size_t(i)];
        break;
      }
    }
  }
  int best = 0;
  for (int j = 1; j < kLabelSlots; ++j) {
    if (roots[j] != 0 && sums[j] > sums[best]) best = j;
  }
  return roots[best];
}

const LabelVoxel* Gsm::labelVoxel(const tsdf::VoxelIndex& v) const {
  const auto it = label_blocks_.find(layer_.blockOfVoxel(v));
  return it == label_blocks_.end() ? nullptr : &it->second[layer_.linearInBlock(v)];
}

Label Gsm::mainLabel(const tsdf::VoxelIndex& v) const {
  const LabelVoxel* voxel = labelVoxel(v);
  return voxel ? mainOf(*voxel) : 0;
}

LabelVoxel& Gsm::labelVoxelFor(const tsdf::VoxelIndex& v) {
  const int vps = layer_.voxelsPerSide();
  auto& block = label_blocks_[layer_.blockOfVoxel(v)];
  if (block.empty()) block.resize(size_t(vps) * vps * vps);
  return block[layer_.linearInBlock(v)];
}

Label Gsm::newLabel() {
  const Label label = next_label_++;
  parent_[label] = label;
  info_[label];
  return label;
}

void Gsm::merge(Label keep, Label gone) {
  keep = resolve(keep);
  gone = resolve(gone);
  if (keep == gone) return;
  if (gone < keep) std::swap(keep, gone);  // the older label survives
  LabelInfo& k = info_[keep];
  LabelInfo& g = info_[gone];
  k.voxels += g.voxels;
  k.last_update_frame = std::max(k.last_update_frame, g.last_update_frame);
  k.extracted_frame = -1;
  k.blocks.insert(g.blocks.begin(), g.blocks.end());
  k.bounds.extend(g.bounds);
  info_.erase(gone);
  parent_[gone] = keep;
}

StatusOr<GsmFrameResult> Gsm::integrate(const DepthImage& depth,
                                        const segmentation::LabelImage& labels,
                                        const Transform& T_world_camera, const ColorImage* color) {
  if (labels.width != depth.width || labels.height != depth.height) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "segment label image is %dx%d but the depth image is %dx%d", labels.width, labels.height,
        depth.width, depth.height));
  }
  GsmFrameResult result;
  // Geometry first: it validates the frame and pose and changes nothing when they are bad.
  OBJDB_ASSIGN_OR_RETURN(result.tsdf, integrator_.integrate(depth, T_world_camera, &layer_, color));

  const Eigen::Isometry3f T = T_world_camera.cast<float>();
  const Intrinsics& k = intrinsics_;
  const int w = depth.width, h = depth.height;
  int32_t n_segments = 0;
  for (int32_t l : labels.data) n_segments = std::max(n_segments, l);
  std::vector<uint32_t> segment_size(size_t(n_segments) + 1, 0);
  absl::flat_hash_map<uint64_t, FrameVotes> votes;  // points bundled per voxel
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const size_t i = size_t(v) * size_t(w) + size_t(u);
      const int32_t s = labels.data[i];
      const float z = depth.data[i];
      if (s <= 0 || !isValidDepth(z) ||
          !(z >= tsdf_params_.min_ray_length_m && z <= tsdf_params_.max_ray_length_m)) {
        continue;
      }
      const Eigen::Vector3f p = T * Eigen::Vector3f(float((u - k.cx) * z / k.fx),
                                                    float((v - k.cy) * z / k.fy), z);
      const tsdf::VoxelIndex voxel = layer_.voxelIndexOf(p);
      ++segment_size[size_t(s)];
      votes[packVoxel(voxel)].add(s);
    }
  }
  // Segment × label overlaps, counted once per voxel from the bundled points.
  absl::flat_hash_map<uint64_t, uint32_t> overlap;  // (segment << 32 | main label) → points
  for (const auto& [key, frame_votes] : votes) {
    const Label g = mainLabel(unpackVoxel(key));
    if (g == 0) continue;
    for (int k = 0; k < 2; ++k) {
      if (frame_votes.segment[k] != 0) {
        overlap[(uint64_t(uint32_t(frame_votes.segment[k])) << 32) | g] += frame_votes.count[k];
      }
    }
  }

  // Greedy association, largest overlap first; at most one segment per label per frame.
  std::vector<std::tuple<uint32_t, int32_t, Label>> pairs;
  for (const auto& [key, n] : overlap) pairs.emplace_back(n, int32_t(key >> 32), Label(key & 0xffffffffULL));
  std::sort(pairs.begin(), pairs.end(), [](const auto& a, const auto& b) {
    return std::get<0>(a) != std::get<0>(b) ? std::get<0>(a) > std::get<0>(b)
                                            : std::tie(std::get<1>(a), std::get<2>(a)) <
                                                  std::tie(std::get<1>(b), std::get<2>(b));
  });
  result.segment_labels.assign(size_t(n_segments), 0);
  absl::flat_hash_set<Label> taken;
  for (const auto& [n, s, g] : pairs) {
    if (result.segment_labels[size_t(s - 1)] != 0 || taken.count(g)) continue;
    if (double(n) < params_.association_overlap_ratio * double(segment_size[size_t(s)])) continue;
    result.segment_labels[size_t(s - 1)] = g;
    taken.insert(g);
  }
  for (int32_t s = 1; s <= n_segments; ++s) {
    if (segment_size[size_t(s)] == 0 || result.segment_labels[size_t(s - 1)] != 0) continue;
    result.segment_labels[size_t(s - 1)] = newLabel();
    ++result.new_labels;
  }

  // Merge evidence: a label covering a good share of a segment that went to another label, and
  // claimed by no segment of its own this frame, is probably the same object.
  absl::flat_hash_set<uint64_t> seen_this_frame;
  for (const auto& [n, s, g] : pairs) {
    const Label assigned = result.segment_labels[size_t(s - 1)];
    if (assigned == 0 || assigned == g || taken.count(g)) continue;
    if (double(n) < params_.merge_overlap_ratio * double(segment_size[size_t(s)])) continue;
    const uint64_t key = packPair(resolve(assigned), resolve(g));
    if (!seen_this_frame.insert(key).second) continue;
    if (++merge_evidence_[key] >= params_.merge_min_frames) {
      merge(assigned, g);
      merge_evidence_.erase(key);
      ++result.merges;
    }
  }
  for (Label& l : result.segment_labels) l = l ? resolve(l) : 0;

  // One vote per voxel per frame, for the segment with most points in it.
  for (const auto& [key, frame_votes] : votes) {
    const int32_t s = frame_votes.winner();
    const Label label = result.segment_labels[size_t(s - 1)];
    if (label == 0) continue;
    const tsdf::VoxelIndex v = unpackVoxel(key);
    LabelVoxel& voxel = labelVoxelFor(v);
    const Label before = voxel.mainLabel();
    if (params_.label_history) {
      voxel.vote(label);
    } else {
      voxel.voteSingle(label);
    }
    const Label after = voxel.mainLabel();
    if (before != after) {
      if (before != 0) --info_[resolve(before)].voxels;
      ++info_[resolve(after)].voxels;
    }
    LabelInfo& info = info_[label];
    info.last_update_frame = frame_;
    info.extracted_frame = -1;
    info.blocks.insert(layer_.blockOfVoxel(v));
    info.bounds.extend(v);
    ++result.voted_voxels;
  }
  ++frame_;
  return result;
}

std::vector<RawSegment> Gsm::extractIdle(bool flush) {
  std::vector<Label> ready;
  for (const auto& [label, info] : info_) {
    if (info.extracted_frame >= 0 || info.last_update_frame < 0) continue;
    const bool idle = frame_ - 1 - info.last_update_frame >= params_.extraction_age_frames;
    if ((flush || idle) && info.voxels >= params_.min_label_voxels) ready.push_back(label);
  }
  std::sort(ready.begin(), ready.end());
  std::vector<RawSegment> segments;
  const int vps = layer_.voxelsPerSide();
  const int margin = int(std::ceil(tsdf_params_.truncation_voxels));
  for (const Label label : ready) {
    LabelInfo& info = info_[label];
    info.extracted_frame = frame_;
    // The label's voxels, found through its block index only (O(object), not O(map)).
    std::vector<tsdf::VoxelIndex> voxels;
    for (const tsdf::BlockIndex& b : info.blocks) {
      const auto it = label_blocks_.find(b);
      if (it == label_blocks_.end()) continue;
      for (size_t i = 0; i < it->second.size(); ++i) {
        if (it->second[i].empty() || mainOf(it->second[i]) != label) continue;
        const int x = int(i % size_t(vps)), y = int((i / size_t(vps)) % size_t(vps)),
                  z = int(i / size_t(vps * vps));
        voxels.push_back(b * vps + Eigen::Vector3i(x, y, z));
      }
    }
    if (voxels.size() < size_t(params_.min_label_voxels)) continue;
    std::sort(voxels.begin(), voxels.end(), [](const auto& a, const auto& b) {
      return std::tie(a.z(), a.y(), a.x()) < std::tie(b.z(), b.y(), b.x());
    });
    Eigen::Vector3i lo = voxels.front(), hi = voxels.front();
    for (const auto& v : voxels) {
      lo = lo.cwiseMin(v);
      hi = hi.cwiseMax(v);
    }
    const tsdf::VoxelIndex origin = lo - Eigen::Vector3i::Constant(margin);
    RawSegment segment{label, Transform::Identity(),
                       tsdf::TsdfLayer::create(layer_.voxelSize(), vps).value(), {},
                       info.last_update_frame, frame_};
    segment.T_world_segment.translation() = origin.cast<double>() * double(layer_.voxelSize());
    for (const auto& v : voxels) {
      segment.label_voxels.push_back(v - origin);
      for (int dz = -margin; dz <= margin; ++dz) {
        for (int dy = -margin; dy <= margin; ++dy) {
          for (int dx = -margin; dx <= margin; ++dx) {
            const tsdf::VoxelIndex src = v + Eigen::Vector3i(dx, dy, dz);
            const tsdf::TsdfVoxel* voxel = layer_.voxel(src);
            if (voxel == nullptr || !(voxel->weight > 0.0f)) continue;
            const tsdf::VoxelIndex dst = src - origin;
            segment.grid.allocateBlock(segment.grid.blockOfVoxel(dst));
            *segment.grid.voxel(dst) = *voxel;
          }
        }
      }
    }
    segments.push_back(std::move(segment));
  }
  return segments;
}

size_t Gsm::labelBytes() const {
  const size_t vps = size_t(layer_.voxelsPerSide());
  return label_blocks_.size() * vps * vps * vps * sizeof(LabelVoxel);
}

}  // namespace objdb::gsm
