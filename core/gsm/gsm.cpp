#include "core/gsm/gsm.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <tuple>

#include "core/common/grid_key.h"
#include "core/common/logging.h"

namespace objdb::gsm {
namespace {

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

// The frame's points bundled per voxel, grouped by block: one hash lookup per block run of
// pixels instead of one per pixel, and one label-block lookup per block in the later passes.
struct Gsm::FrameScratch {
  struct Block {
    tsdf::BlockIndex index;
    std::vector<FrameVotes> votes;   // voxels_per_side³, all empty between frames
    std::vector<uint32_t> touched;   // linear indices with votes this frame
  };
  std::vector<Block> blocks;         // the first `used` are this frame's
  size_t used = 0;
  absl::flat_hash_map<tsdf::BlockIndex, uint32_t, tsdf::BlockIndexHash> slot;

  Block& blockFor(const tsdf::BlockIndex& index, size_t voxels_per_block) {
    auto [it, inserted] = slot.try_emplace(index, uint32_t(used));
    if (!inserted) return blocks[it->second];
    if (used == blocks.size()) blocks.emplace_back();
    Block& block = blocks[used++];
    block.index = index;
    if (block.votes.size() != voxels_per_block) block.votes.assign(voxels_per_block, FrameVotes{});
    return block;
  }
  void reset() {
    for (size_t i = 0; i < used; ++i) {
      for (uint32_t v : blocks[i].touched) blocks[i].votes[v] = FrameVotes{};
      blocks[i].touched.clear();
    }
    used = 0;
    slot.clear();
  }
};

Gsm::Gsm(Gsm&&) noexcept = default;
Gsm& Gsm::operator=(Gsm&&) noexcept = default;
Gsm::~Gsm() = default;

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
      layer_(std::move(layer)),
      scratch_(std::make_unique<FrameScratch>()) {}

Label Gsm::resolve(Label label) const {
  if (label >= parent_.size()) return label;
  while (parent_[label] != label) label = parent_[label];
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

LabelBlocks Gsm::mainLabelBlocks() const {
  LabelBlocks out;
  out.reserve(label_blocks_.size());
  for (const auto& [index, voxels] : label_blocks_) {
    std::vector<Label> labels(voxels.size());
    bool any = false;
    for (size_t i = 0; i < voxels.size(); ++i) {
      labels[i] = mainOf(voxels[i]);
      any = any || labels[i] != 0;
    }
    if (any) out.emplace(index, std::move(labels));
  }
  return out;
}

Label Gsm::newLabel() {
  const Label label = next_label_++;
  parent_.push_back(label);
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
  k.frames = std::max(k.frames, g.frames);
  k.extracted_frame = -1;
  if (g.extracted_voxels > 0) withdrawn_.push_back(gone);  // its voxels now come with `keep`
  k.blocks.insert(g.blocks.begin(), g.blocks.end());
  k.bounds.extend(g.bounds);
  info_.erase(gone);
  parent_[gone] = keep;
  // The pair evidence of the merged-away label now belongs to the survivor (summed where both
  // had some with the same partner); the pair itself is gone. Merges are rare: a linear scan.
  std::vector<std::pair<Label, PairEvidence>> moved;
  for (auto it = pair_evidence_.begin(); it != pair_evidence_.end();) {
    const Label a = Label(it->first >> 32), b = Label(it->first & 0xffffffffULL);
    if (a != gone && b != gone) {
      ++it;
      continue;
    }
    const Label partner = a == gone ? b : a;
    if (partner != keep) moved.emplace_back(partner, it->second);
    pair_evidence_.erase(it++);
  }
  pair_evidence_.erase(packPair(keep, gone));
  for (const auto& [partner, e] : moved) {
    PairEvidence& to = pair_evidence_[packPair(keep, partner)];
    to.joint += e.joint;
    to.separate += e.separate;
  }
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
  using Clock = std::chrono::steady_clock;
  const auto ms = [](Clock::time_point a, Clock::time_point b) {
    return std::chrono::duration<double, std::milli>(b - a).count();
  };
  const auto t_start = Clock::now();
  // The frame against the map before it is fused (the residuals count once it fused).
  SurfaceNoise frame_noise(surface_noise_.model());
  frame_noise.sample(layer_, depth, T_world_camera, intrinsics_,
                     tsdf_params_.truncationDistance());
  // Geometry first: it validates the frame and pose and changes nothing when they are bad.
  OBJDB_ASSIGN_OR_RETURN(result.tsdf, integrator_.integrate(depth, T_world_camera, &layer_, color));
  surface_noise_.add(frame_noise);
  const auto t_integrated = Clock::now();
  result.timings.integration_ms = ms(t_start, t_integrated);

  const Eigen::Isometry3f T = T_world_camera.cast<float>();
  const Intrinsics& k = intrinsics_;
  const int w = depth.width, h = depth.height;
  const int vps = layer_.voxelsPerSide();
  const size_t voxels_per_block = size_t(vps) * size_t(vps) * size_t(vps);
  int32_t n_segments = 0;
  for (int32_t l : labels.data) n_segments = std::max(n_segments, l);
  std::vector<uint32_t> segment_size(size_t(n_segments) + 1, 0);
  FrameScratch& scratch = *scratch_;
  scratch.reset();
  // Points bundled per voxel; consecutive pixels mostly fall into the same block.
  FrameScratch::Block* current = nullptr;
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
      const tsdf::BlockIndex block = layer_.blockOfVoxel(voxel);
      if (current == nullptr || current->index != block) {
        current = &scratch.blockFor(block, voxels_per_block);
      }
      const Eigen::Vector3i local = voxel - block * vps;
      const size_t lin =
          size_t(local.x()) + size_t(vps) * (size_t(local.y()) + size_t(vps) * size_t(local.z()));
      FrameVotes& frame_votes = current->votes[lin];
      if (frame_votes.segment[0] == 0) current->touched.push_back(uint32_t(lin));
      frame_votes.add(s);
      ++segment_size[size_t(s)];
    }
  }
  // Segment × label overlaps, counted once per voxel from the bundled points.
  absl::flat_hash_map<uint64_t, uint32_t> overlap;  // (segment << 32 | main label) → points
  for (size_t b = 0; b < scratch.used; ++b) {
    const FrameScratch::Block& block = scratch.blocks[b];
    const auto it = label_blocks_.find(block.index);
    if (it == label_blocks_.end()) continue;
    for (uint32_t lin : block.touched) {
      const Label g = mainOf(it->second[lin]);
      if (g == 0) continue;
      const FrameVotes& frame_votes = block.votes[lin];
      for (int j = 0; j < 2; ++j) {
        if (frame_votes.segment[j] != 0) {
          overlap[(uint64_t(uint32_t(frame_votes.segment[j])) << 32) | g] += frame_votes.count[j];
        }
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
    if (assigned == 0 || resolve(assigned) == resolve(g)) continue;
    const uint64_t key = packPair(resolve(assigned), resolve(g));
    if (taken.count(g)) {
      // Touching, and each claimed by its own segment: evidence that they are two objects.
      if (params_.merge_min_joint_share > 0.0f && seen_this_frame.insert(key).second) {
        ++pair_evidence_[key].separate;
      }
      continue;
    }
    if (double(n) < params_.merge_overlap_ratio * double(segment_size[size_t(s)])) continue;
    if (!seen_this_frame.insert(key).second) continue;
    PairEvidence& e = pair_evidence_[key];
    ++e.joint;
    if (e.joint >= params_.merge_min_frames &&
        double(e.joint) >= double(params_.merge_min_joint_share) * double(e.joint + e.separate)) {
      merge(assigned, g);
      pair_evidence_.erase(key);
      ++result.merges;
    }
  }
  for (Label& l : result.segment_labels) l = l ? resolve(l) : 0;
  const auto t_associated = Clock::now();
  result.timings.association_ms = ms(t_integrated, t_associated);

  // One vote per voxel per frame, for the segment with most points in it. Per block, the
  // labels voted for are gathered first so their bookkeeping is updated once per block.
  struct BlockLabel {
    Label label;
    Eigen::AlignedBox3i bounds;
  };
  std::vector<BlockLabel> block_labels;
  for (size_t b = 0; b < scratch.used; ++b) {
    const FrameScratch::Block& block = scratch.blocks[b];
    std::vector<LabelVoxel>& label_block = label_blocks_[block.index];
    if (label_block.empty()) label_block.resize(voxels_per_block);
    const tsdf::VoxelIndex block_origin = block.index * vps;
    block_labels.clear();
    for (uint32_t lin : block.touched) {
      const int32_t s = block.votes[lin].winner();
      const Label label = result.segment_labels[size_t(s - 1)];
      if (label == 0) continue;
      LabelVoxel& voxel = label_block[lin];
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
      const tsdf::VoxelIndex v =
          block_origin + tsdf::VoxelIndex(int(lin % uint32_t(vps)),
                                          int((lin / uint32_t(vps)) % uint32_t(vps)),
                                          int(lin / uint32_t(vps * vps)));
      auto it = std::find_if(block_labels.begin(), block_labels.end(),
                             [&](const BlockLabel& bl) { return bl.label == label; });
      if (it == block_labels.end()) {
        block_labels.push_back({label, Eigen::AlignedBox3i(v)});
      } else {
        it->bounds.extend(v);
      }
      ++result.voted_voxels;
    }
    for (const BlockLabel& bl : block_labels) {
      LabelInfo& info = info_[bl.label];
      if (info.last_update_frame != frame_) ++info.frames;
      info.last_update_frame = frame_;
      info.extracted_frame = -1;
      info.blocks.insert(block.index);
      info.bounds.extend(bl.bounds);
    }
  }
  camera_positions_.push_back(T_world_camera.translation().cast<float>());
  camera_up_sum_ -= T_world_camera.linear().col(1);  // image y points down
  ++frame_;
  result.timings.voting_ms = ms(t_associated, Clock::now());
  return result;
}

namespace {

// The voxels of block `b` for which `keep(i)` holds (i = the voxel's index in the block),
// appended to `voxels`.
template <typename Keep>
void appendBlockVoxels(const tsdf::BlockIndex& b, size_t count, int vps, Keep&& keep,
                       std::vector<tsdf::VoxelIndex>* voxels) {
  for (size_t i = 0; i < count; ++i) {
    if (!keep(i)) continue;
    const int x = int(i % size_t(vps)), y = int((i / size_t(vps)) % size_t(vps)),
              z = int(i / size_t(vps * vps));
    voxels->push_back(b * vps + Eigen::Vector3i(x, y, z));
  }
}

// An object's voxels as objects.h defines them: its parts' own (`voxels`), less those on a
// bounding face of the room (cut) and those another object took from a structure label, plus the
// structure voxels it took itself.
void applyAnnexed(Label id, const ObjectGroups& groups, std::vector<tsdf::VoxelIndex>* voxels) {
  if (groups.annexed_part.empty() && groups.cut.empty()) return;
  voxels->erase(std::remove_if(voxels->begin(), voxels->end(),
                               [&](const tsdf::VoxelIndex& v) {
                                 const uint64_t key = packGridKey(v);
                                 return groups.annexed_part.contains(key) || groups.cut.contains(key);
                               }),
                voxels->end());
  const auto it = groups.annexed.find(id);
  if (it == groups.annexed.end()) return;
  for (const AnnexedVoxel& a : it->second) voxels->push_back(a.voxel);
}

std::vector<uint64_t> sortedKeys(const std::vector<tsdf::VoxelIndex>& voxels) {
  std::vector<uint64_t> keys;
  keys.reserve(voxels.size());
  for (const tsdf::VoxelIndex& v : voxels) keys.push_back(packGridKey(v));
  std::sort(keys.begin(), keys.end());
  return keys;
}

// The share of the larger of two sorted key sets that the other lacks (0 when both are empty):
// what an object gained or lost, whichever is more.
double changedShare(const std::vector<uint64_t>& a, const std::vector<uint64_t>& b) {
  size_t common = 0;
  for (size_t i = 0, j = 0; i < a.size() && j < b.size();) {
    if (a[i] < b[j]) {
      ++i;
    } else if (b[j] < a[i]) {
      ++j;
    } else {
      ++common, ++i, ++j;
    }
  }
  const size_t larger = std::max(a.size(), b.size());
  return larger == 0 ? 0.0 : 1.0 - double(common) / double(larger);
}

}  // namespace

RawSegment extractRawSegment(const tsdf::TsdfLayer& layer, Label label,
                             std::vector<tsdf::VoxelIndex> voxels, int margin,
                             int64_t last_update_frame, int64_t frame,
                             const std::function<Label(const tsdf::VoxelIndex&)>& part_of) {
  std::sort(voxels.begin(), voxels.end(), [](const auto& a, const auto& b) {
    return std::tie(a.z(), a.y(), a.x()) < std::tie(b.z(), b.y(), b.x());
  });
  RawSegment segment{label, Transform::Identity(),
                     tsdf::TsdfLayer::create(layer.voxelSize(), layer.voxelsPerSide()).value(),
                     {}, last_update_frame, frame, 0.0f, {}, {}};
  if (voxels.empty()) return segment;
  Eigen::Vector3i lo = voxels.front();
  for (const auto& v : voxels) lo = lo.cwiseMin(v);
  const tsdf::VoxelIndex origin = lo - Eigen::Vector3i::Constant(margin);
  segment.T_world_segment.translation() = origin.cast<double>() * double(layer.voxelSize());
  for (const auto& v : voxels) {
    segment.label_voxels.push_back(v - origin);
    segment.voxel_parts.push_back(part_of ? part_of(v) : label);
    for (int dz = -margin; dz <= margin; ++dz) {
      for (int dy = -margin; dy <= margin; ++dy) {
        for (int dx = -margin; dx <= margin; ++dx) {
          const tsdf::VoxelIndex src = v + Eigen::Vector3i(dx, dy, dz);
          const tsdf::TsdfVoxel* voxel = layer.voxel(src);
          if (voxel == nullptr || !(voxel->weight > 0.0f)) continue;
          const tsdf::VoxelIndex dst = src - origin;
          segment.grid.allocateBlock(segment.grid.blockOfVoxel(dst));
          *segment.grid.voxel(dst) = *voxel;
        }
      }
    }
  }
  return segment;
}

std::vector<RawSegment> extractLabelled(const tsdf::TsdfLayer& layer, const LabelBlocks& labels,
                                        const GsmParams& params, int margin, int64_t frame) {
  const int vps = layer.voxelsPerSide();
  absl::flat_hash_map<Label, std::vector<tsdf::BlockIndex>> blocks_of;
  for (const auto& [index, block] : labels) {
    absl::flat_hash_set<Label> seen;
    for (const Label l : block) {
      if (l != 0 && seen.insert(l).second) blocks_of[l].push_back(index);
    }
  }
  // One segment per object (its parts' voxels together), or per label.
  ObjectGroups groups;
  if (params.objects) {
    groups = groupObjects(layer, labels, params);
  } else {
    for (const auto& [label, unused] : blocks_of) groups.members[label] = {label};
  }
  std::vector<RawSegment> segments;
  for (const auto& [id, parts] : groups.members) {
    std::vector<tsdf::VoxelIndex> voxels;
    for (const Label label : parts) {
      for (const tsdf::BlockIndex& b : blocks_of[label]) {
        const std::vector<Label>& block = labels.at(b);
        appendBlockVoxels(b, block.size(), vps, [&](size_t i) { return block[i] == label; },
                          &voxels);
      }
    }
    applyAnnexed(id, groups, &voxels);
    if (voxels.size() < size_t(std::max(params.min_label_voxels, 1))) continue;
    segments.push_back(extractRawSegment(
        layer, id, std::move(voxels), margin, frame, frame, [&](const tsdf::VoxelIndex& v) {
          return groups.partAt(v, labels.at(layer.blockOfVoxel(v))[layer.linearInBlock(v)]);
        }));
    segments.back().parts = parts;
    if (params.objects) {
      segments.back().structure = parts.size() == 1 && groups.structure.contains(parts.front());
    }
  }
  return segments;
}

std::vector<RawSegment> Gsm::extractIdle(bool flush) {
  return params_.objects ? extractIdleObjects(flush) : extractIdleLabels(flush);
}

ObjectGroups Gsm::groupObjects() const {
  return gsm::groupObjects(layer_, mainLabelBlocks(), params_, upHint());
}

Eigen::Vector3f Gsm::upHint() const {
  if (camera_positions_.empty()) return Eigen::Vector3f::Zero();
  const Eigen::Vector3d mean = camera_up_sum_ / double(camera_positions_.size());
  return mean.norm() >= 0.5 ? Eigen::Vector3f(mean.normalized().cast<float>())
                            : Eigen::Vector3f::Zero();
}

std::vector<tsdf::VoxelIndex> Gsm::voxelsOf(const std::vector<Label>& labels) const {
  const int vps = layer_.voxelsPerSide();
  absl::flat_hash_set<tsdf::BlockIndex, tsdf::BlockIndexHash> blocks;
  for (const Label l : labels) {
    const auto it = info_.find(l);
    if (it != info_.end()) blocks.insert(it->second.blocks.begin(), it->second.blocks.end());
  }
  std::vector<tsdf::VoxelIndex> voxels;
  for (const tsdf::BlockIndex& b : blocks) {
    const auto it = label_blocks_.find(b);
    if (it == label_blocks_.end()) continue;
    const std::vector<LabelVoxel>& block = it->second;
    appendBlockVoxels(b, block.size(), vps, [&](size_t i) {
      return !block[i].empty() && std::binary_search(labels.begin(), labels.end(), mainOf(block[i]));
    }, &voxels);
  }
  return voxels;
}

float Gsm::observationDepth(const std::vector<tsdf::VoxelIndex>& voxels, int64_t frame) const {
  if (voxels.empty() || frame < 0 || size_t(frame) >= camera_positions_.size()) return 0.0f;
  const Eigen::Vector3f camera = camera_positions_[size_t(frame)];
  std::vector<float> depths;
  depths.reserve(voxels.size());
  for (const auto& v : voxels) depths.push_back((layer_.voxelCenter(v) - camera).norm());
  std::nth_element(depths.begin(), depths.begin() + long(depths.size() / 2), depths.end());
  return depths[depths.size() / 2];
}

std::vector<RawSegment> Gsm::extractIdleLabels(bool flush) {
  std::vector<Label> ready;
  for (auto& [label, info] : info_) {
    if (info.extracted_frame >= 0 || info.last_update_frame < 0) continue;
    const bool idle = frame_ - 1 - info.last_update_frame >= params_.extraction_age_frames;
    if (!flush && !idle) continue;
    if (info.voxels >= params_.min_label_voxels) {
      ready.push_back(label);
    } else if (info.extracted_voxels > 0) {  // too small now: its earlier segment is withdrawn
      withdrawn_.push_back(label);
      info.extracted_voxels = 0;
      info.extracted_frame = frame_;
    }
  }
  std::sort(ready.begin(), ready.end());
  std::vector<RawSegment> segments;
  const int margin = int(std::ceil(tsdf_params_.truncation_voxels));
  for (const Label label : ready) {
    LabelInfo& info = info_[label];
    info.extracted_frame = frame_;
    // The label's voxels, found through its block index only (O(object), not O(map)).
    std::vector<tsdf::VoxelIndex> voxels = voxelsOf({label});
    if (voxels.size() < size_t(params_.min_label_voxels)) {
      if (info.extracted_voxels > 0) withdrawn_.push_back(label);
      info.extracted_voxels = 0;
      continue;
    }
    info.extracted_voxels = int64_t(voxels.size());
    const float depth = observationDepth(voxels, info.last_update_frame);
    segments.push_back(extractRawSegment(layer_, label, std::move(voxels), margin,
                                         info.last_update_frame, frame_));
    segments.back().observation_depth_m = depth;
    segments.back().noise_scale = surface_noise_.scale();
    segments.back().parts = {label};
  }
  return segments;
}

std::vector<RawSegment> Gsm::extractIdleObjects(bool flush) {
  if (flush || grouped_frame_ < 0 || frame_ - grouped_frame_ >= params_.object_update_frames) {
    grouped_frame_ = frame_;
    // The room structure every structure_update_frames frames and at a flush; the regroupings
    // between reuse the last one.
    const bool fresh_room = flush || room_frame_ < 0 ||
                            frame_ - room_frame_ >= params_.structure_update_frames;
    RoomStructure room = std::move(groups_.room);
    if (fresh_room) {
      room_frame_ = frame_;
      groups_ = groupObjects();
    } else {
      groups_ = gsm::groupObjects(layer_, mainLabelBlocks(), params_, upHint(), &room);
    }
    logger("gsm")->debug("frame {}: room structure: {}; {} giant objects fell back to parts, {} "
                         "standing units kept apart",
                         frame_, groups_.room.summary(), groups_.giant_fallbacks,
                         groups_.standing_cuts);
    // An object extracted before whose id is no object now went into another (or vanished).
    std::vector<Label> gone;
    for (const auto& [id, extracted] : extracted_objects_) {
      if (!groups_.members.count(id)) gone.push_back(id);
    }
    std::sort(gone.begin(), gone.end());
    for (const Label id : gone) {
      withdrawn_.push_back(id);
      extracted_objects_.erase(id);
      ++extraction_counts_.withdrawn;
    }
  }
  // Idleness is checked every frame, on the groups of the last regrouping (their labels resolved
  // through the merges since).
  std::vector<RawSegment> segments;
  const int margin = int(std::ceil(tsdf_params_.truncation_voxels));
  const auto resolveAll = [this](std::vector<Label>* labels) {  // through the merges; sorted
    for (Label& l : *labels) l = resolve(l);
    std::sort(labels->begin(), labels->end());
    labels->erase(std::unique(labels->begin(), labels->end()), labels->end());
  };
  for (auto& [id, parts] : groups_.members) {
    resolveAll(&parts);
    int64_t last_update = -1, frames = 0;
    for (const Label l : parts) {
      const auto it = info_.find(l);
      if (it == info_.end()) continue;
      last_update = std::max(last_update, it->second.last_update_frame);
      frames = std::max(frames, it->second.frames);
    }
    if (last_update < 0) continue;
    const bool idle = frame_ - 1 - last_update >= params_.extraction_age_frames;
    if (!flush && !idle) continue;
    const auto earlier = extracted_objects_.find(id);
    if (earlier != extracted_objects_.end() && earlier->second.parts == parts &&
        earlier->second.frame > last_update) {
      continue;  // extracted since its last change
    }
    if (!flush && earlier == extracted_objects_.end() && frames < params_.object_min_frames) {
      // Flicker so far (GsmParams::object_min_frames): looked at again when it is voted for, and
      // at the flush (what still stands then was a surface seen once, not taken back).
      unconfirmed_.insert(id);
      extraction_counts_.unconfirmed = unconfirmed_.size();
      continue;
    }
    std::vector<tsdf::VoxelIndex> voxels = voxelsOf(parts);
    applyAnnexed(id, groups_, &voxels);
    if (voxels.size() < size_t(params_.min_label_voxels)) {
      if (earlier != extracted_objects_.end()) {
        withdrawn_.push_back(id);
        extracted_objects_.erase(earlier);
        ++extraction_counts_.withdrawn;
      }
      continue;
    }
    std::vector<uint64_t> keys = sortedKeys(voxels);
    if (earlier != extracted_objects_.end()) {
      // The same parts as then (through the merges since), and its voxels barely changed: its
      // stored segment stands, and the change is measured against it next time too. A part that
      // joined or left re-extracts it: the database would lack a joined part's voxels (its own
      // object withdrawn) or hold a leaving part's twice.
      std::vector<Label> then = earlier->second.parts;
      resolveAll(&then);
      if (then == parts &&
          changedShare(earlier->second.voxels, keys) < params_.reextract_min_change) {
        earlier->second.parts = parts;
        earlier->second.frame = frame_;
        ++extraction_counts_.unchanged;
        continue;
      }
      ++extraction_counts_.again;
    } else {
      ++extraction_counts_.first;
    }
    extracted_objects_[id] = ExtractedObject{parts, std::move(keys), frame_};
    const float depth = observationDepth(voxels, last_update);
    segments.push_back(
        extractRawSegment(layer_, id, std::move(voxels), margin, last_update, frame_,
                          [this, &parts](const tsdf::VoxelIndex& v) {
                            // Always one of the object's parts (the store refuses anything else).
                            const Label main = mainLabel(v);
                            if (std::binary_search(parts.begin(), parts.end(), main)) return main;
                            // An annexed voxel: the part that took it, through the merges since;
                            // the object's first if that went elsewhere. Its own label may be one
                            // that is newer than the grouping (not known as structure there), so
                            // it is looked up by voxel, not through partAt's structure test.
                            const auto it = groups_.annexed_part.find(packGridKey(v));
                            const Label now = it == groups_.annexed_part.end() ? 0 : resolve(it->second);
                            return std::binary_search(parts.begin(), parts.end(), now)
                                       ? now
                                       : parts.front();
                          }));
    segments.back().observation_depth_m = depth;
    segments.back().noise_scale = surface_noise_.scale();
    segments.back().parts = parts;
    // A structure label is an object of its own (the grouping joins it to nothing).
    segments.back().structure = parts.size() == 1 && (groups_.structure.contains(id) ||
                                                      groups_.structure.contains(parts.front()));
  }
  return segments;
}

std::vector<Label> Gsm::takeWithdrawn() {
  std::vector<Label> out;
  out.swap(withdrawn_);
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

size_t Gsm::labelBytes() const {
  const size_t vps = size_t(layer_.voxelsPerSide());
  return label_blocks_.size() * vps * vps * vps * sizeof(LabelVoxel);
}

}  // namespace objdb::gsm
