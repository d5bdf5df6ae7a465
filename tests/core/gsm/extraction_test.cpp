// When the GSM hands an object to the database (Gsm::extractIdle with GsmParams::objects): not
// while it is flicker seen in one frame (object_min_frames), and not again when it was updated
// but its voxels barely changed (reextract_min_change).
#include <algorithm>
#include <set>
#include <vector>

#include <gtest/gtest.h>

#include "core/gsm/gsm.h"
#include "core/segmentation/depth_segmenter.h"
#include "core/sim/generator.h"
#include "core/sim/lounge.h"
#include "tests/support/furniture_scene.h"

namespace objdb::gsm {
namespace {

using testing::makeGsm;
using testing::objectOf;
using Scene = testing::FurnitureScene;

std::set<Label> ids(const std::vector<RawSegment>& segments) {
  std::set<Label> out;
  for (const RawSegment& s : segments) out.insert(s.label);
  return out;
}

GsmParams everyFrame() {
  GsmParams params;
  params.extraction_age_frames = 1;
  params.object_update_frames = 1;
  return params;
}

// A chair (seat 10, back 11, legs 12-15) on the floor, fused from `frames` cameras; then two
// frames whose segments carry no label, so every label is idle. The chair's object id.
Label fuseChair(const Scene& scene, Gsm* gsm, int frames) {
  const auto label_of = scene.fuse(gsm, Eigen::Vector3d(0, 0, 0.4), frames);
  scene.fuse(gsm, Eigen::Vector3d(0, 0, 0.4), 2, 0.3, {99});
  return objectOf(gsm->groupObjects(), label_of, 10);
}

// A map of the chair seen in `frames` frames, and its object id.
struct ChairMap {
  Scene scene;
  Gsm gsm;
  Label chair = 0;
};
ChairMap chairSeenIn(int frames, const GsmParams& params = everyFrame()) {
  ChairMap m{Scene(), makeGsm(params), 0};
  m.scene.addChair(Eigen::Vector3d::Zero(), 10);
  m.chair = fuseChair(m.scene, &m.gsm, frames);
  return m;
}

TEST(Extraction, AnObjectSeenInOneFrameIsHeldBackUntilTheFlush) {
  ChairMap m = chairSeenIn(1);
  Gsm& gsm = m.gsm;
  const Label chair = m.chair;
  ASSERT_NE(chair, 0u);
  EXPECT_FALSE(ids(gsm.extractIdle()).count(chair)) << "idle, but seen in one frame only";
  EXPECT_GE(gsm.extractionCounts().unconfirmed, 1u);
  EXPECT_EQ(gsm.extractionCounts().first, 0u);
  EXPECT_TRUE(ids(gsm.extractIdle(true)).count(chair)) << "the flush takes what still stands";
}

TEST(Extraction, AnObjectSeenInTwoFramesIsExtractedWhenIdle) {
  ChairMap m = chairSeenIn(2);
  ASSERT_NE(m.chair, 0u);
  EXPECT_TRUE(ids(m.gsm.extractIdle()).count(m.chair));
  EXPECT_GE(m.gsm.extractionCounts().first, 1u);
}

TEST(Extraction, WithObjectMinFramesOneAnObjectSeenOnceIsExtractedWhenIdle) {
  GsmParams params = everyFrame();
  params.object_min_frames = 1;
  ChairMap m = chairSeenIn(1, params);
  ASSERT_NE(m.chair, 0u);
  EXPECT_TRUE(ids(m.gsm.extractIdle()).count(m.chair));
  EXPECT_EQ(m.gsm.extractionCounts().unconfirmed, 0u);
}

// Seen all round, extracted; then seen all round again from the same cameras: updated, but its
// voxels are those it had, so the database keeps the segment it has (counted as unchanged).
// With reextract_min_change 0 (the paper: every update) it is extracted again.
TEST(Extraction, AnObjectSeenAgainAsBeforeIsNotExtractedAgain) {
  for (const float min_change : {0.1f, 0.0f}) {
    SCOPED_TRACE(::testing::Message() << "reextract_min_change " << min_change);
    GsmParams params = everyFrame();
    params.reextract_min_change = min_change;
    ChairMap m = chairSeenIn(8, params);
    Gsm& gsm = m.gsm;
    const Scene& scene = m.scene;
    const Label chair = m.chair;
    ASSERT_NE(chair, 0u);
    ASSERT_TRUE(ids(gsm.extractIdle()).count(chair));
    EXPECT_TRUE(gsm.extractIdle().empty()) << "nothing changed since";
    ASSERT_EQ(fuseChair(scene, &gsm, 8), chair);
    const bool again = ids(gsm.extractIdle()).count(chair) > 0;
    EXPECT_EQ(again, min_change == 0.0f);
    // (The floor, an object of its own, is seen again too.)
    EXPECT_EQ(gsm.extractionCounts().again >= 1, min_change == 0.0f);
    EXPECT_EQ(gsm.extractionCounts().unchanged >= 1, min_change > 0.0f);
    EXPECT_TRUE(gsm.takeWithdrawn().empty()) << "its stored segment stands either way";
  }
}


// Every voxel of an extracted object names one of its parts (the store refuses anything else;
// before, ListObjects with parts failed with DATA_LOSS). The lounge's second session through the
// real segmenter, extracting as the server does every frame: a voxel an object annexed from a
// structure label whose voxels changed label after the grouping named that newer label.
TEST(Extraction, EveryVoxelOfAnExtractedObjectIsOneOfItsParts) {
  const auto sessions = sim::loungePreset();
  ASSERT_TRUE(sessions.ok()) << sessions.status();
  const sim::Scene& scene = (*sessions)[1];
  const auto built = sim::buildScene(scene);
  ASSERT_TRUE(built.ok()) << built.status();
  const auto poses = sim::sampleTrajectory(scene.trajectory);
  ASSERT_TRUE(poses.ok());
  const sim::Renderer renderer(scene.intrinsics);
  auto segmenter =
      segmentation::DepthSegmenter::create(SegmentationParams{}, scene.intrinsics).value();
  Gsm gsm = Gsm::create(TsdfParams{}, GsmParams{}, scene.intrinsics).value();
  size_t segments = 0;
  const auto check = [&](const std::vector<RawSegment>& extracted) {
    for (const RawSegment& s : extracted) {
      ++segments;
      ASSERT_EQ(s.voxel_parts.size(), s.label_voxels.size()) << "segment " << s.label;
      for (const Label part : s.voxel_parts) {
        ASSERT_TRUE(std::binary_search(s.parts.begin(), s.parts.end(), part))
            << "segment " << s.label << ": a voxel of part " << part << ", not one of "
            << ::testing::PrintToString(s.parts);
      }
    }
  };
  for (size_t f = 0; f < poses->size(); ++f) {
    const Frame frame = sim::renderFrame(scene, *built, renderer, (*poses)[f], f, false);
    const auto seg = segmenter.segment(frame.depth, nullptr);
    ASSERT_TRUE(seg.ok()) << seg.status();
    ASSERT_TRUE(gsm.integrate(frame.depth, seg->labels, frame.T_world_camera).ok());
    check(gsm.extractIdle());
    if (HasFatalFailure()) return;
  }
  check(gsm.extractIdle(/*flush=*/true));
  EXPECT_GT(segments, 50u);
}

}  // namespace
}  // namespace objdb::gsm
