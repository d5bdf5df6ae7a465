#include "core/gsm/gsm.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <set>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "core/sim/renderer.h"
#include "core/sim/shapes.h"

namespace objdb::gsm {
namespace {

// A box (instance 2) standing on a floor (instance 1), seen from a few poses around it.
struct World {
  TriangleMesh floor = sim::makePlane(6.0f, 6.0f, 0.5f);
  TriangleMesh box = sim::makeBox({0.5f, 0.4f, 0.4f});
  Transform T_world_box = Transform::Identity();
  World() { T_world_box.translation() = Eigen::Vector3d(0, 0, 0.2); }
  std::vector<sim::RenderInstance> instances() const {
    return {sim::RenderInstance{&floor, Transform::Identity(), 1},
            sim::RenderInstance{&box, T_world_box, 2}};
  }
  Transform camera(double angle_rad) const {
    return lookAt(Eigen::Vector3d(1.6 * std::cos(angle_rad), 1.6 * std::sin(angle_rad), 1.2),
                  Eigen::Vector3d(0, 0, 0.2))
        .value();
  }
};

// The first and last image column the box (instance 2) covers.
std::pair<int, int> boxColumns(const InstanceImage& instances) {
  int u_min = instances.width, u_max = 0;
  for (int v = 0; v < instances.height; ++v) {
    for (int u = 0; u < instances.width; ++u) {
      if (instances.at(u, v) == 2) {
        u_min = std::min(u_min, u);
        u_max = std::max(u_max, u);
      }
    }
  }
  return {u_min, u_max};
}

segmentation::LabelImage labelsFrom(const InstanceImage& instances, bool split_box) {
  segmentation::LabelImage labels(instances.width, instances.height, 0);
  const auto [u_min, u_max] = boxColumns(instances);
  const int middle = (u_min + u_max) / 2;
  for (int v = 0; v < instances.height; ++v) {
    for (int u = 0; u < instances.width; ++u) {
      const uint16_t id = instances.at(u, v);
      if (id == 1) labels.at(u, v) = 1;
      if (id == 2) labels.at(u, v) = split_box && u > middle ? 3 : 2;
    }
  }
  return labels;
}

Gsm makeGsm(const Intrinsics& k, GsmParams params = {}) {
  TsdfParams tsdf;
  tsdf.voxel_size_m = 0.02f;
  return Gsm::create(tsdf, params, k).value();
}

TEST(Gsm, ConsistentLabelsAcrossFramesForTheSameObject) {
  const Intrinsics k = Intrinsics::tango();
  const World world;
  Gsm gsm = makeGsm(k);
  const sim::Renderer renderer(k);
  sim::RenderOutput out;
  Label box_label = 0, floor_label = 0;
  for (int f = 0; f < 5; ++f) {
    const Transform T = world.camera(0.2 * f);
    renderer.render(world.instances(), T, &out);
    auto labels = labelsFrom(out.instances, false);
    if (f % 2 == 1) {  // per-frame labels need not agree: swap them every other frame
      for (int32_t& l : labels.data) l = l == 1 ? 2 : l == 2 ? 1 : l;
    }
    auto r = gsm.integrate(out.depth, labels, T);
    ASSERT_TRUE(r.ok()) << r.status();
    const Label floor_now = r->segment_labels[f % 2 == 1 ? 1 : 0];
    const Label box_now = r->segment_labels[f % 2 == 1 ? 0 : 1];
    if (f == 0) {
      floor_label = floor_now;
      box_label = box_now;
      EXPECT_EQ(r->new_labels, 2u);
    } else {
      EXPECT_EQ(floor_now, floor_label) << "frame " << f;
      EXPECT_EQ(box_now, box_label) << "frame " << f;
      EXPECT_EQ(r->new_labels, 0u);
    }
  }
  EXPECT_NE(box_label, floor_label);
  EXPECT_EQ(gsm.numLabels(), 2u);
}

TEST(Gsm, TwoSegmentsOfOneObjectGetMergedAfterAFewFrames) {
  const Intrinsics k = Intrinsics::tango();
  const World world;
  GsmParams params;  // merge after 2 frames of evidence at overlap ≥ 0.1
  Gsm gsm = makeGsm(k, params);
  const sim::Renderer renderer(k);
  sim::RenderOutput out;
  // Frame 0: the box comes as two segments → two labels.
  renderer.render(world.instances(), world.camera(0.0), &out);
  auto r = gsm.integrate(out.depth, labelsFrom(out.instances, true), world.camera(0.0));
  ASSERT_TRUE(r.ok());
  const Label left = r->segment_labels[1], right = r->segment_labels[2];
  ASSERT_NE(left, right);
  // Then the whole box as one segment: both labels overlap it.
  size_t merges = 0;
  for (int f = 1; f <= 3; ++f) {
    renderer.render(world.instances(), world.camera(0.05 * f), &out);
    r = gsm.integrate(out.depth, labelsFrom(out.instances, false), world.camera(0.05 * f));
    ASSERT_TRUE(r.ok());
    merges += r->merges;
    if (f == 1) {
      EXPECT_NE(gsm.resolve(left), gsm.resolve(right)) << "one frame is not evidence enough";
    }
  }
  EXPECT_EQ(merges, 1u);
  EXPECT_EQ(gsm.resolve(left), gsm.resolve(right));
  EXPECT_EQ(gsm.resolve(right), std::min(left, right));  // the older label survives
  EXPECT_EQ(gsm.numLabels(), 2u);                         // floor + box
  // Merging is lossless: voxels voted for either half now report the merged label.
  size_t box_voxels = 0;
  for (const auto& [label, info] : gsm.labels()) {
    if (label == gsm.resolve(left)) box_voxels = size_t(info.voxels);
  }
  EXPECT_GT(box_voxels, 100u);
  // Its bounds cover the box (0.5 × 0.4 × 0.4 m at 2 cm voxels: about 25 × 20 × 20 voxels).
  const Eigen::AlignedBox3i& bounds = gsm.labels().at(gsm.resolve(left)).bounds;
  ASSERT_FALSE(bounds.isEmpty());
  EXPECT_NEAR(bounds.sizes().z(), 20, 3);
  EXPECT_GE(bounds.sizes().x(), 18);
  // The label blocks a scene map stores give every voxel its main label after the merge.
  const LabelBlocks blocks = gsm.mainLabelBlocks();
  ASSERT_FALSE(blocks.empty());
  size_t labelled = 0;
  const int vps = gsm.tsdf().voxelsPerSide();
  for (const auto& [index, labels] : blocks) {
    ASSERT_EQ(labels.size(), size_t(vps * vps * vps));
    for (int z = 0; z < vps; ++z) {
      for (int y = 0; y < vps; ++y) {
        for (int x = 0; x < vps; ++x) {
          const tsdf::VoxelIndex v = index * vps + tsdf::VoxelIndex(x, y, z);
          const Label l = labels[gsm.tsdf().linearInBlock(v)];
          ASSERT_EQ(l, gsm.mainLabel(v));
          ASSERT_NE(l, right == gsm.resolve(left) ? left : right);  // the merged-away label
          labelled += l != 0 ? 1 : 0;
        }
      }
    }
  }
  EXPECT_GT(labelled, box_voxels);  // box and floor
}

// A label extracted before its GSM merge is withdrawn: the survivor's next segment holds its
// voxels, so whoever kept its segment must drop it (else one surface is kept twice).
TEST(Gsm, ALabelExtractedBeforeItMergedIsWithdrawnOnce) {
  const Intrinsics k = Intrinsics::tango();
  const World world;
  GsmParams labels_alone;  // label extraction (objects_test covers the objects')
  labels_alone.objects = false;
  Gsm gsm = makeGsm(k, labels_alone);
  const sim::Renderer renderer(k);
  sim::RenderOutput out;
  renderer.render(world.instances(), world.camera(0.0), &out);
  auto r = gsm.integrate(out.depth, labelsFrom(out.instances, true), world.camera(0.0));
  ASSERT_TRUE(r.ok());
  const Label left = r->segment_labels[1], right = r->segment_labels[2];
  // Both halves extracted (a flush), nothing withdrawn yet.
  std::set<Label> extracted;
  for (const auto& s : gsm.extractIdle(true)) extracted.insert(s.label);
  ASSERT_TRUE(extracted.count(left) && extracted.count(right));
  EXPECT_TRUE(gsm.takeWithdrawn().empty());
  // The whole box as one segment until the halves merge; the newer label goes.
  for (int f = 1; f <= 3; ++f) {
    renderer.render(world.instances(), world.camera(0.05 * f), &out);
    ASSERT_TRUE(gsm.integrate(out.depth, labelsFrom(out.instances, false), world.camera(0.05 * f)).ok());
  }
  ASSERT_EQ(gsm.resolve(right), left);
  EXPECT_EQ(gsm.takeWithdrawn(), std::vector<Label>{right});
  EXPECT_TRUE(gsm.takeWithdrawn().empty()) << "returned once";
  // The survivor comes out again with both halves' voxels.
  bool survivor = false;
  for (const auto& s : gsm.extractIdle(true)) survivor = survivor || s.label == left;
  EXPECT_TRUE(survivor);
}

// Two labels seen apart in most frames (each claimed by its own segment) are not merged by a
// couple of frames in which one segment covered both, unless merge_min_joint_share is 0 (the
// paper's rule); they merge once the joint frames reach that share of all frames seeing both.
TEST(Gsm, LabelsSeenApartNeedJointFramesInProportionToMerge) {
  const Intrinsics k = Intrinsics::tango();
  const World world;
  const sim::Renderer renderer(k);
  sim::RenderOutput out;
  for (const float share : {0.0f, 0.5f}) {
    GsmParams params;
    params.merge_min_joint_share = share;
    Gsm gsm = makeGsm(k, params);
    int f = 0;
    auto frame = [&](bool split) {
      const Transform T = world.camera(0.03 * f++);
      renderer.render(world.instances(), T, &out);
      auto r = gsm.integrate(out.depth, labelsFrom(out.instances, split), T);
      EXPECT_TRUE(r.ok()) << r.status();
      return r.ok() ? r->merges : size_t(0);
    };
    // Apart: the box as two segments, two labels that touch (the first frame creates them, the
    // next five are evidence that they are two objects).
    for (int i = 0; i < 6; ++i) EXPECT_EQ(frame(true), 0u);
    // The two halves are the labels other than the floor's (the largest).
    std::vector<std::pair<int64_t, Label>> by_size;
    for (const auto& [label, info] : gsm.labels()) by_size.emplace_back(info.voxels, label);
    ASSERT_EQ(by_size.size(), 3u);
    std::sort(by_size.rbegin(), by_size.rend());
    const Label left = by_size[1].second, right = by_size[2].second;
    frame(false);
    frame(false);  // two joint frames: the paper's evidence
    if (share == 0.0f) {
      EXPECT_EQ(gsm.resolve(left), gsm.resolve(right)) << "the paper's rule merges after 2";
      continue;
    }
    EXPECT_NE(gsm.resolve(left), gsm.resolve(right)) << "5 frames apart outweigh 2 together";
    // Joint frames 3 and 4 are still fewer than half of the frames seeing both; the 5th is half.
    EXPECT_EQ(frame(false), 0u);
    EXPECT_EQ(frame(false), 0u);
    EXPECT_NE(gsm.resolve(left), gsm.resolve(right));
    EXPECT_EQ(frame(false), 1u);
    EXPECT_EQ(gsm.resolve(left), gsm.resolve(right)) << "5 frames together, 5 apart";
  }
}

// The floor 1, and the box cut into three vertical slices (left, middle, right) whose segment
// labels are given (0: the slice is in no segment).
segmentation::LabelImage sliceLabels(const InstanceImage& instances,
                                     const std::array<int32_t, 3>& slice_label) {
  const auto [u_min, u_max] = boxColumns(instances);
  segmentation::LabelImage labels(instances.width, instances.height, 0);
  const int width = std::max(1, u_max - u_min + 1);
  for (int v = 0; v < instances.height; ++v) {
    for (int u = 0; u < instances.width; ++u) {
      const uint16_t id = instances.at(u, v);
      if (id == 1) labels.at(u, v) = 1;
      if (id == 2) labels.at(u, v) = slice_label[size_t(std::min(2, 3 * (u - u_min) / width))];
    }
  }
  return labels;
}

// When a label merges into another, what was known about its neighbours goes with it: the left
// slice, seen apart from the middle one for many frames, does not merge with the middle+right
// label after two joint frames just because the middle label merged away.
TEST(Gsm, AMergeHandsThePairEvidenceToTheSurvivingLabel) {
  const Intrinsics k = Intrinsics::tango();
  const World world;
  const sim::Renderer renderer(k);
  sim::RenderOutput out;
  Gsm gsm = makeGsm(k);  // merge_min_joint_share 0.5
  int f = 0;
  auto frame = [&](const std::array<int32_t, 3>& slices) {
    const Transform T = world.camera(0.02 * f++);
    renderer.render(world.instances(), T, &out);
    auto r = gsm.integrate(out.depth, sliceLabels(out.instances, slices), T);
    EXPECT_TRUE(r.ok()) << r.status();
    return r.ok() ? r->segment_labels : std::vector<Label>{};
  };
  // Frame 0: left and right slices only, so the middle label is the newest of the three.
  const std::vector<Label> first = frame({2, 0, 3});
  ASSERT_EQ(first.size(), 3u);
  const Label left = first[1], right = first[2];
  // Six frames apart: three segments, three labels.
  Label middle = 0;
  for (int i = 0; i < 6; ++i) {
    const std::vector<Label> labels = frame({2, 3, 4});
    ASSERT_EQ(labels.size(), 4u);
    EXPECT_EQ(labels[1], left);
    EXPECT_EQ(labels[3], right);
    middle = labels[2];
  }
  ASSERT_NE(middle, 0u);
  ASSERT_LT(right, middle);
  // Middle and right as one segment until their labels merge (the older, right, survives).
  for (int i = 0; i < 20 && gsm.resolve(middle) != gsm.resolve(right); ++i) frame({2, 3, 3});
  ASSERT_EQ(gsm.resolve(middle), right);
  // Now the whole box as one segment: two joint frames do not outweigh the frames apart.
  frame({2, 2, 2});
  frame({2, 2, 2});
  EXPECT_NE(gsm.resolve(left), gsm.resolve(right))
      << "the left/middle evidence was lost when the middle label merged";
}

TEST(Gsm, IdleLabelIsExtractedExactlyOnceWithItsPoseAndVoxels) {
  const Intrinsics k = Intrinsics::tango();
  const World world;
  GsmParams params;
  params.extraction_age_frames = 3;
  params.objects = false;  // labels alone; objects_test covers the objects' extraction
  Gsm gsm = makeGsm(k, params);
  const sim::Renderer renderer(k);
  sim::RenderOutput out;
  Label box = 0;
  for (int f = 0; f < 4; ++f) {
    renderer.render(world.instances(), world.camera(0.3 * f), &out);
    auto r = gsm.integrate(out.depth, labelsFrom(out.instances, false), world.camera(0.3 * f));
    ASSERT_TRUE(r.ok());
    box = r->segment_labels[1];
  }
  EXPECT_TRUE(gsm.extractIdle().empty());  // just updated
  // Frames that see only the floor: the box label ages.
  std::vector<RawSegment> extracted;
  int frames_until_extraction = 0;
  while (extracted.empty() && frames_until_extraction < 10) {
    renderer.render({world.instances()[0]}, world.camera(3.0), &out);
    auto labels = labelsFrom(out.instances, false);
    ASSERT_TRUE(gsm.integrate(out.depth, labels, world.camera(3.0)).ok());
    ++frames_until_extraction;
    for (auto& s : gsm.extractIdle()) extracted.push_back(std::move(s));
  }
  // Last updated in frame 3; idle for extraction_age_frames = 3 frames after it.
  EXPECT_EQ(frames_until_extraction, 3);
  ASSERT_EQ(extracted.size(), 1u) << "the box once; the floor is still being updated";
  const RawSegment& s = extracted[0];
  EXPECT_EQ(s.label, box);
  EXPECT_EQ(s.last_update_frame, 3);
  EXPECT_GE(s.label_voxels.size(), size_t(params.min_label_voxels));
  // Every label voxel lies on the box surface (within a voxel and a half), in world coordinates.
  const Transform T_box_world = world.T_world_box.inverse();
  for (const auto& v : s.label_voxels) {
    const Eigen::Vector3d p_world =
        s.T_world_segment * s.grid.voxelCenter(v).cast<double>();
    const Eigen::Vector3d p = T_box_world * p_world;
    const double outside = (p.cwiseAbs() - Eigen::Vector3d(0.25, 0.2, 0.2)).maxCoeff();
    ASSERT_LT(std::abs(outside), 0.03) << p.transpose();
  }
  // The grid holds the TSDF around them, identical to the map's voxels.
  size_t copied = 0;
  for (const auto& [index, block] : s.grid.blocks()) {
    for (size_t i = 0; i < block->voxels().size(); ++i) {
      const tsdf::TsdfVoxel& voxel = block->voxels()[i];
      if (!(voxel.weight > 0.0f)) continue;
      const int vps = s.grid.voxelsPerSide();
      const tsdf::VoxelIndex local = index * vps + Eigen::Vector3i(int(i % vps), int((i / vps) % vps), int(i / (vps * vps)));
      const Eigen::Vector3d world_point = s.T_world_segment * s.grid.voxelCenter(local).cast<double>();
      const tsdf::TsdfVoxel* map_voxel = gsm.tsdf().voxel(gsm.tsdf().voxelIndexOf(world_point.cast<float>()));
      ASSERT_NE(map_voxel, nullptr);
      ASSERT_EQ(map_voxel->distance, voxel.distance);
      ++copied;
    }
  }
  EXPECT_GT(copied, s.label_voxels.size());
  // Nothing more comes out until the label is updated again; a flush still skips it.
  EXPECT_TRUE(gsm.extractIdle().empty());
  for (const auto& f : gsm.extractIdle(true)) EXPECT_NE(f.label, box);
}

// A session ended from its saved map (TSDF + main labels, no label histories) hands the database
// the same raw segments as the GSM's own flush at the end of the session.
TEST(Gsm, SegmentsExtractedFromTheSavedMapAreThoseOfTheFlush) {
  const Intrinsics k = Intrinsics::tango();
  const World world;
  Gsm gsm = makeGsm(k);
  const sim::Renderer renderer(k);
  sim::RenderOutput out;
  for (int f = 0; f < 6; ++f) {
    renderer.render(world.instances(), world.camera(0.25 * f), &out);
    ASSERT_TRUE(gsm.integrate(out.depth, labelsFrom(out.instances, f % 2 == 0),
                              world.camera(0.25 * f)).ok());
  }
  const tsdf::TsdfLayer saved = gsm.tsdf().clone();
  const LabelBlocks labels = gsm.mainLabelBlocks();
  const GsmParams params;
  const int margin = int(std::ceil(TsdfParams().truncation_voxels));
  const std::vector<RawSegment> from_saved =
      extractLabelled(saved, labels, params, margin, gsm.frames());
  const std::vector<RawSegment> flushed = gsm.extractIdle(true);
  ASSERT_GE(flushed.size(), 2u) << "the floor and the box";
  ASSERT_EQ(from_saved.size(), flushed.size());
  for (size_t i = 0; i < flushed.size(); ++i) {
    SCOPED_TRACE(::testing::Message() << "label " << flushed[i].label);
    EXPECT_EQ(from_saved[i].label, flushed[i].label);
    EXPECT_TRUE(from_saved[i].T_world_segment.isApprox(flushed[i].T_world_segment, 1e-12));
    EXPECT_EQ(from_saved[i].label_voxels, flushed[i].label_voxels);
    EXPECT_EQ(from_saved[i].extraction_frame, gsm.frames());
    ASSERT_EQ(from_saved[i].grid.numBlocks(), flushed[i].grid.numBlocks());
    for (const auto& [index, block] : flushed[i].grid.blocks()) {
      const tsdf::TsdfBlock* other = from_saved[i].grid.block(index);
      ASSERT_NE(other, nullptr);
      for (size_t v = 0; v < block->voxels().size(); ++v) {
        ASSERT_EQ(other->voxels()[v].distance, block->voxels()[v].distance);
        ASSERT_EQ(other->voxels()[v].weight, block->voxels()[v].weight);
      }
    }
  }
  // Labels below the minimum size are left out, as the flush leaves them.
  GsmParams huge = params;
  huge.min_label_voxels = 1 << 30;
  EXPECT_TRUE(extractLabelled(saved, labels, huge, margin, gsm.frames()).empty());
}

TEST(Gsm, BadFramesAreRefusedAndLeaveTheMapUnchanged) {
  const Intrinsics k = Intrinsics::tango();
  Gsm gsm = makeGsm(k);
  const DepthImage depth(k.width, k.height, 1.5f);
  segmentation::LabelImage labels(k.width, k.height, 1);
  auto r = gsm.integrate(depth, segmentation::LabelImage(10, 10, 1), Transform::Identity());
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("10x10"), absl::string_view::npos);
  Transform bad = Transform::Identity();
  bad.linear()(0, 0) = std::nan("");
  EXPECT_EQ(gsm.integrate(depth, labels, bad).status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(gsm.tsdf().numBlocks(), 0u);
  EXPECT_EQ(gsm.numLabels(), 0u);
  EXPECT_EQ(gsm.frames(), 0);
  EXPECT_TRUE(gsm.integrate(depth, labels, Transform::Identity()).ok());
  EXPECT_EQ(gsm.numLabels(), 1u);
  EXPECT_GT(gsm.labelBytes(), 0u);
}

}  // namespace
}  // namespace objdb::gsm
