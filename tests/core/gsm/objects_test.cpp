#include "core/gsm/objects.h"

#include <cmath>
#include <map>
#include <set>
#include <vector>

#include <gtest/gtest.h>

#include "core/common/grid_key.h"
#include "core/gsm/gsm.h"
#include "core/sim/renderer.h"
#include "core/sim/shapes.h"
#include "tests/support/furniture_scene.h"

namespace objdb::gsm {
namespace {

using testing::FurnitureScene;
using Scene = FurnitureScene;

using testing::makeGsm;
using testing::objectOf;

TEST(Objects, AChairOnAFloorIsOneObjectOfItsSixParts) {
  Scene scene;
  scene.addChair(Eigen::Vector3d::Zero(), 10);
  Gsm gsm = makeGsm();
  const auto label_of = scene.fuse(&gsm, Eigen::Vector3d(0, 0, 0.4));
  const ObjectGroups g = gsm.groupObjects();
  const Label chair = objectOf(g, label_of, 10);
  ASSERT_NE(chair, 0u);
  for (uint16_t id = 11; id <= 15; ++id) {
    EXPECT_EQ(objectOf(g, label_of, id), chair) << "part " << id << " belongs to the chair";
  }
  EXPECT_EQ(g.members.at(chair).size(), 6u) << "the parts keep their labels";
  EXPECT_EQ(chair, *std::min_element(g.members.at(chair).begin(), g.members.at(chair).end()));
  EXPECT_TRUE(g.structure.count(label_of.at(1))) << "the floor is structure";
  EXPECT_NE(objectOf(g, label_of, 1), chair);
  EXPECT_EQ(g.members.at(objectOf(g, label_of, 1)).size(), 1u) << "structure stays alone";
}

TEST(Objects, TwoChairsFiveCentimetresApartStayTwoObjects) {
  Scene scene;
  scene.addChair(Eigen::Vector3d(-0.25, 0, 0), 10);
  scene.addChair(Eigen::Vector3d(0.25, 0, 0), 20);  // seats 5 cm apart
  Gsm gsm = makeGsm();
  const auto label_of = scene.fuse(&gsm, Eigen::Vector3d(0, 0, 0.4));
  const ObjectGroups g = gsm.groupObjects();
  const Label left = objectOf(g, label_of, 10), right = objectOf(g, label_of, 20);
  ASSERT_NE(left, 0u);
  ASSERT_NE(right, 0u);
  EXPECT_NE(left, right);
  for (uint16_t id = 11; id <= 15; ++id) EXPECT_EQ(objectOf(g, label_of, id), left) << id;
  for (uint16_t id = 21; id <= 25; ++id) EXPECT_EQ(objectOf(g, label_of, id), right) << id;
}

// A table (instances 10 … 14) with a mug (30) standing on its top, off its middle.
Scene tableWithMug() {
  Scene scene;
  scene.addTable(Eigen::Vector3d::Zero(), 10);
  scene.add(sim::makeCylinder(0.045f, 0.11f), Eigen::Vector3d(0.1, 0.05, 0.74), 30);
  return scene;
}

TEST(Objects, AMugOnATableIsItsOwnObject) {
  const Scene scene = tableWithMug();
  Gsm gsm = makeGsm();
  const auto label_of = scene.fuse(&gsm, Eigen::Vector3d(0, 0, 0.5));
  const ObjectGroups g = gsm.groupObjects();
  const Label table = objectOf(g, label_of, 10), mug = objectOf(g, label_of, 30);
  ASSERT_NE(table, 0u);
  ASSERT_NE(mug, 0u);
  EXPECT_NE(mug, table) << "the mug rests on the table top";
  EXPECT_EQ(g.members.at(mug).size(), 1u);
  for (uint16_t id = 11; id <= 14; ++id) EXPECT_EQ(objectOf(g, label_of, id), table) << "leg " << id;
  EXPECT_GE(g.supports, 1u);
}

TEST(Objects, WithoutTheSupportRuleTheMugWouldJoinTheTable) {
  // The rule is what separates them: a probe of 0 m finds no surface around the contact.
  const Scene scene = tableWithMug();
  GsmParams params;
  params.object_support_probe_m = 0.0f;
  Gsm gsm = makeGsm(params);
  const auto label_of = scene.fuse(&gsm, Eigen::Vector3d(0, 0, 0.5));
  const ObjectGroups g = gsm.groupObjects();
  EXPECT_EQ(objectOf(g, label_of, 30), objectOf(g, label_of, 10));
}

// The scene fused at 2 cm around `centre` (FurnitureScene::fuse) and grouped, with the labels.
struct Grouping {
  ObjectGroups groups;
  std::map<uint16_t, Label> label_of;
};
Grouping fuseAndGroup(const Scene& scene, const Eigen::Vector3d& centre) {
  Gsm gsm = makeGsm();
  auto label_of = scene.fuse(&gsm, centre);
  return {gsm.groupObjects(), std::move(label_of)};
}

TEST(Objects, AChairPushedAgainstATableStaysItsOwnObject) {
  // The hard case (docs/gsm.md): the seat's front edge touches a table leg. The chair stands on
  // its own legs and the table on its own: two objects.
  Scene scene;
  scene.addTable(Eigen::Vector3d::Zero(), 10);
  // The chair faces the table (+y) with its seat's front edge against the leg at (−0.45, −0.3).
  scene.addChair(Eigen::Vector3d(-0.45, -0.3 - 0.025 - 0.225, 0), 20);
  const auto [g, label_of] = fuseAndGroup(scene, Eigen::Vector3d(0, -0.2, 0.5));
  const Label table = objectOf(g, label_of, 10), chair = objectOf(g, label_of, 20);
  ASSERT_NE(table, 0u);
  ASSERT_NE(chair, 0u);
  EXPECT_NE(chair, table);
  EXPECT_GE(g.standing_cuts, 1u);
  for (uint16_t id = 21; id <= 25; ++id) EXPECT_EQ(objectOf(g, label_of, id), chair) << id;
  for (uint16_t id = 11; id <= 14; ++id) EXPECT_EQ(objectOf(g, label_of, id), table) << id;
}

TEST(Objects, AStandingCrumbUnderATableAndAChairJoinsOneOfThemOnly) {
  // A chair (seat 20, back 21, its four legs one label 22) half under a table (top 10, its four
  // legs one label 11), not touching it; a thin standing crumb (30) between the chair's front
  // leg and the table's leg touches both and lies under both footprints (so it is one base
  // with either). It joins one; the chair and the table stay two objects.
  Scene scene;
  scene.addBox({1.0f, 0.7f, 0.04f}, Eigen::Vector3d(0, 0, 0.72), 10);
  for (const double x : {-0.45, 0.45}) {
    for (const double y : {-0.3, 0.3}) {
      scene.addBox({0.05f, 0.05f, 0.70f}, Eigen::Vector3d(x, y, 0.35), 11);
    }
  }
  const Eigen::Vector3d chair(0.2, -0.4, 0.0);
  scene.addBox({0.45f, 0.45f, 0.04f}, chair + Eigen::Vector3d(0, 0, 0.45), 20);
  scene.addBox({0.45f, 0.04f, 0.45f}, chair + Eigen::Vector3d(0, -0.205, 0.695), 21);
  for (const double x : {-0.19, 0.19}) {
    for (const double y : {-0.19, 0.19}) {
      scene.addBox({0.04f, 0.04f, 0.43f}, chair + Eigen::Vector3d(x, y, 0.215), 22);
    }
  }
  scene.addBox({0.035f, 0.065f, 0.2f}, Eigen::Vector3d(0.4175, -0.2525, 0.1), 30);
  const auto [g, label_of] = fuseAndGroup(scene, Eigen::Vector3d(0, -0.2, 0.4));
  const Label table = objectOf(g, label_of, 10), seat = objectOf(g, label_of, 20);
  ASSERT_NE(table, 0u);
  ASSERT_NE(seat, 0u);
  ASSERT_NE(objectOf(g, label_of, 30), 0u) << "the crumb has a label";
  EXPECT_NE(seat, table);
  EXPECT_EQ(objectOf(g, label_of, 11), table);
  EXPECT_EQ(objectOf(g, label_of, 22), seat);
  EXPECT_TRUE(objectOf(g, label_of, 30) == table || objectOf(g, label_of, 30) == seat);
}

TEST(Objects, WithoutAFloorAChairPushedAgainstATableJoinsIt) {
  // The safe answer where nothing says what stands: the floor is fused but carries no label, so
  // no floor is found and every contact connects.
  Scene scene;
  scene.addTable(Eigen::Vector3d::Zero(), 10);
  scene.addChair(Eigen::Vector3d(-0.45, -0.3 - 0.025 - 0.225, 0), 20);
  Gsm gsm = makeGsm();
  std::set<uint16_t> parts;
  for (uint16_t id = 10; id <= 14; ++id) parts.insert(id);
  for (uint16_t id = 20; id <= 25; ++id) parts.insert(id);
  const auto label_of = scene.fuse(&gsm, Eigen::Vector3d(0, -0.2, 0.5), 16, 0.0, parts);
  const ObjectGroups g = gsm.groupObjects();
  EXPECT_EQ(objectOf(g, label_of, 20), objectOf(g, label_of, 10));
  EXPECT_EQ(g.standing_cuts, 0u);
}

TEST(Objects, AnObjectKeepsItsGroupingInASecondSessionAndFromTheSavedMap) {
  Scene scene;
  scene.addChair(Eigen::Vector3d::Zero(), 10);
  size_t parts_first = 0;
  for (int session = 0; session < 2; ++session) {
    SCOPED_TRACE(::testing::Message() << "session " << session);
    Gsm gsm = makeGsm();
    // The second session sees the chair from other poses, fewer of them.
    const auto label_of = scene.fuse(&gsm, Eigen::Vector3d(0, 0, 0.4), session == 0 ? 16 : 11,
                                     session == 0 ? 0.0 : 0.37);
    const std::vector<RawSegment> flushed = gsm.extractIdle(true);
    const RawSegment* chair = nullptr;
    for (const auto& s : flushed) {
      if (s.label == objectOf(gsm.groupObjects(), label_of, 10)) chair = &s;
    }
    ASSERT_NE(chair, nullptr);
    if (session == 0) parts_first = chair->parts.size();
    EXPECT_EQ(chair->parts.size(), 6u);
    EXPECT_EQ(chair->parts.size(), parts_first);
    // Every voxel names its part, and every part has voxels.
    ASSERT_EQ(chair->voxel_parts.size(), chair->label_voxels.size());
    std::map<Label, size_t> voxels_of;
    for (const Label part : chair->voxel_parts) ++voxels_of[part];
    ASSERT_EQ(voxels_of.size(), chair->parts.size());
    for (const Label part : chair->parts) EXPECT_GT(voxels_of[part], 0u) << "part " << part;
    // From the saved map (a restart ends the session from it): the same object, the same parts.
    const auto from_saved = extractLabelled(gsm.tsdf(), gsm.mainLabelBlocks(), GsmParams{},
                                            int(std::ceil(TsdfParams().truncation_voxels)),
                                            gsm.frames());
    bool found = false;
    for (const auto& s : from_saved) {
      if (s.label != chair->label) continue;
      found = true;
      EXPECT_EQ(s.parts, chair->parts);
      EXPECT_EQ(s.label_voxels, chair->label_voxels);
      EXPECT_EQ(s.voxel_parts, chair->voxel_parts);
    }
    EXPECT_TRUE(found);
  }
}

TEST(Objects, AnObjectWhosePartsJoinAnOlderOneIsWithdrawnAndTheOlderReextracted) {
  // First only the back and a front leg get segments: two objects (they do not touch). Then
  // the seat, which joins them: one object under the back's (older) id, re-extracted with the
  // three parts; the leg's object is withdrawn once.
  Scene scene;
  scene.addChair(Eigen::Vector3d::Zero(), 10);
  GsmParams params;
  params.extraction_age_frames = 1;
  params.object_update_frames = 1;
  Gsm gsm = makeGsm(params);
  auto label_of = scene.fuse(&gsm, Eigen::Vector3d(0, 0, 0.4), 8, 0.0, {11, 13});
  const std::vector<RawSegment> first = gsm.extractIdle(true);
  const ObjectGroups before = gsm.groupObjects();
  const Label back = objectOf(before, label_of, 11), leg = objectOf(before, label_of, 13);
  ASSERT_NE(back, 0u);
  ASSERT_NE(leg, 0u);
  ASSERT_LT(back, leg);  // the back got the first label
  std::set<Label> ids;
  for (const auto& s : first) ids.insert(s.label);
  EXPECT_TRUE(ids.count(back) && ids.count(leg)) << "two objects";
  EXPECT_TRUE(gsm.extractIdle().empty()) << "nothing changed since";
  const auto later = scene.fuse(&gsm, Eigen::Vector3d(0, 0, 0.4), 8, 0.1, {10, 11, 13});
  const std::vector<RawSegment> again = gsm.extractIdle(true);
  const RawSegment* chair = nullptr;
  for (const auto& s : again) {
    if (s.label == back) chair = &s;
    EXPECT_NE(s.label, leg);
  }
  ASSERT_NE(chair, nullptr) << "re-extracted under the older id";
  std::set<Label> parts(chair->parts.begin(), chair->parts.end());
  EXPECT_TRUE(parts.count(later.at(11))) << "the back";
  EXPECT_TRUE(parts.count(later.at(13))) << "the leg";
  EXPECT_TRUE(parts.count(later.at(10))) << "the seat";
  EXPECT_EQ(gsm.takeWithdrawn(), std::vector<Label>{leg});
  EXPECT_TRUE(gsm.takeWithdrawn().empty()) << "once";
}

// The voxels of object `id` in the segments a flush extracts (map voxel indices), with parts.
std::map<uint64_t, Label> extractedVoxels(Gsm* gsm, Label id) {
  std::map<uint64_t, Label> out;
  for (const RawSegment& s : gsm->extractIdle(true)) {
    if (s.label != id) continue;
    const tsdf::VoxelIndex origin =
        (s.T_world_segment.translation() / double(gsm->tsdf().voxelSize()))
            .array()
            .round()
            .cast<int>()
            .matrix();
    for (size_t i = 0; i < s.label_voxels.size(); ++i) {
      out[packGridKey(s.label_voxels[i] + origin)] = s.voxel_parts[i];
    }
  }
  return out;
}

// A map of one pedestal chair (seat 10, column 11) on the floor (1), and its objects.
struct Grouped {
  Scene scene;
  Gsm gsm;
  std::map<uint16_t, Label> label_of;
  ObjectGroups groups;
};
Grouped pedestalChair(const GsmParams& params = {}) {
  Grouped out{Scene(), makeGsm(params), {}, {}};
  out.scene.addPedestalChair(Eigen::Vector3d::Zero(), 10);
  out.label_of = out.scene.fuse(&out.gsm, Eigen::Vector3d(0, 0, 0.3));
  out.groups = out.gsm.groupObjects();
  return out;
}

TEST(Objects, APedestalChairIsOneObjectWithTheBaseTheFloorWasLabelledWith) {
  Grouped map = pedestalChair();
  Gsm& gsm = map.gsm;
  const auto& label_of = map.label_of;
  const ObjectGroups& g = map.groups;
  const Label chair = objectOf(g, label_of, 10);
  ASSERT_NE(chair, 0u);
  EXPECT_EQ(objectOf(g, label_of, 11), chair) << "the column joins the seat across its shadow";
  EXPECT_GE(g.shadow_joins, 1u);
  // The base: floor-labelled voxels standing off the floor, inside the chair's footprint.
  ASSERT_TRUE(g.annexed.count(chair));
  const std::vector<AnnexedVoxel>& base = g.annexed.at(chair);
  EXPECT_GE(base.size(), 150u) << "most of the base's top (a disc of 0.2 m², 490 voxels)";
  for (const AnnexedVoxel& a : base) {
    const Eigen::Vector3f c = gsm.tsdf().voxelCenter(a.voxel);
    EXPECT_GT(c.z(), 0.0f);
    EXPECT_LT(c.z(), 0.1f);
    EXPECT_LT(c.head<2>().norm(), 0.25f + 0.05f);
    EXPECT_EQ(gsm.mainLabel(a.voxel), label_of.at(1)) << "a floor voxel";
    EXPECT_EQ(a.part, label_of.at(11)) << "joined as part of the column it touches";
  }
  // Extracted with the chair, as part of the column, and no longer with the floor.
  const Label floor = objectOf(g, label_of, 1);
  const std::map<uint64_t, Label> chair_voxels = extractedVoxels(&gsm, chair);
  Grouped again = pedestalChair();
  const std::map<uint64_t, Label> floor_voxels = extractedVoxels(&again.gsm, floor);
  ASSERT_FALSE(floor_voxels.empty());
  for (const AnnexedVoxel& a : base) {
    const auto it = chair_voxels.find(packGridKey(a.voxel));
    ASSERT_NE(it, chair_voxels.end());
    EXPECT_EQ(it->second, label_of.at(11));
    EXPECT_FALSE(floor_voxels.count(packGridKey(a.voxel)));
  }
  // The saved map's extraction (a restart) gives the same voxels and parts.
  const auto from_saved = extractLabelled(gsm.tsdf(), gsm.mainLabelBlocks(), GsmParams{},
                                          int(std::ceil(TsdfParams().truncation_voxels)),
                                          gsm.frames());
  bool found = false;
  for (const auto& s : from_saved) {
    if (s.label != chair) continue;
    found = true;
    EXPECT_EQ(s.label_voxels.size(), chair_voxels.size());
    std::map<Label, size_t> parts;
    for (const Label p : s.voxel_parts) ++parts[p];
    EXPECT_GE(parts[label_of.at(11)], base.size());
  }
  EXPECT_TRUE(found);
}

TEST(Objects, WithoutTheShadowRuleThePedestalIsAnObjectOfItsOwn) {
  GsmParams params;
  params.object_shadow_gap_m = 0.0f;
  const Grouped map = pedestalChair(params);
  ASSERT_NE(objectOf(map.groups, map.label_of, 10), 0u);
  EXPECT_NE(objectOf(map.groups, map.label_of, 11), objectOf(map.groups, map.label_of, 10));
  EXPECT_EQ(map.groups.shadow_joins, 0u);
}

TEST(Objects, WithoutAnnexingTheBaseStaysWithTheFloor) {
  GsmParams params;
  params.object_annex_height_m = 0.0f;
  const Grouped map = pedestalChair(params);
  EXPECT_TRUE(map.groups.annexed.empty());
  EXPECT_TRUE(map.groups.annexed_part.empty());
}

TEST(Objects, AFloatingSeatTakesTheBaseUnderItWhenItsColumnCarriesNoLabel) {
  // At a coarse camera the thin column gets no segment (fused as surface, never labelled): the
  // seat touches nothing and floats, and no labelled voxel reaches the base. The base, an island
  // of floor voxels off the floor's plane under the seat's footprint, is the seat's foot.
  Grouped out{Scene(), makeGsm(), {}, {}};
  out.scene.addPedestalChair(Eigen::Vector3d::Zero(), 10);
  out.label_of = out.scene.fuse(&out.gsm, Eigen::Vector3d(0, 0, 0.3), 16, 0.0, {1, 10});
  out.groups = out.gsm.groupObjects();
  const ObjectGroups& g = out.groups;
  ASSERT_FALSE(out.label_of.count(11));
  const Label chair = objectOf(g, out.label_of, 10);
  ASSERT_NE(chair, 0u);
  EXPECT_GE(g.islands, 1u);
  ASSERT_TRUE(g.annexed.count(chair));
  const std::vector<AnnexedVoxel>& base = g.annexed.at(chair);
  EXPECT_GE(base.size(), 150u) << "most of the base's top (a disc of 0.2 m², 490 voxels)";
  for (const AnnexedVoxel& a : base) {
    const Eigen::Vector3f c = out.gsm.tsdf().voxelCenter(a.voxel);
    EXPECT_GT(c.z(), 0.0f);
    EXPECT_LT(c.z(), 0.1f);
    EXPECT_LT(c.head<2>().norm(), 0.25f + 0.05f);
    EXPECT_EQ(out.gsm.mainLabel(a.voxel), out.label_of.at(1)) << "a floor voxel";
    EXPECT_EQ(a.part, out.label_of.at(10)) << "joined as part of the seat, its only part";
  }
}

TEST(Objects, AMatUnderAShelfOnTheWallStaysWithTheFloor) {
  // A mat 3 cm high, segmented with the floor, under a shelf board 0.5 m up: an island off the
  // floor's plane under the board's footprint, with the board above the annexed band. But the
  // board is fixed to a wall (structure, instance 2), so nothing unseen carries it and the mat
  // is no foot of it.
  Scene scene;
  scene.addBox({3.0f, 0.1f, 2.0f}, Eigen::Vector3d(0, -0.25, 1.0), 2);
  scene.addBox({0.6f, 0.3f, 0.03f}, Eigen::Vector3d(0, 0.0, 0.5), 10);
  scene.addBox({0.5f, 0.25f, 0.03f}, Eigen::Vector3d(0, 0.0, 0.015), 1);
  Gsm gsm = makeGsm();
  const auto label_of = scene.fuse(&gsm, Eigen::Vector3d(0, 0, 0.3));
  const ObjectGroups g = gsm.groupObjects();
  const Label shelf = objectOf(g, label_of, 10);
  ASSERT_NE(shelf, 0u);
  ASSERT_TRUE(g.structure.contains(label_of.at(2))) << "the wall is structure";
  EXPECT_NE(shelf, objectOf(g, label_of, 2));
  EXPECT_EQ(g.islands, 0u);
  EXPECT_FALSE(g.annexed.count(shelf));
}

// A table (top 0.95 × 0.95 m at 0.70–0.74 m, instance 10, with four legs 11 … 14 or without)
// and a post (instance 30, 0.1 × 0.1 m, 0.45 m high) under the middle of its top. Seen from
// 2.5 m, the top's shadow reaches down to ~0.2 m there: the post's upper half and the 0.25 m
// above it are never seen (0.5 m of shadow between what is seen of both), and the post touches
// nothing but the floor.
Scene tableOverPost(bool legs) {
  Scene scene;
  scene.addBox({0.95f, 0.95f, 0.04f}, Eigen::Vector3d(0, 0, 0.72), 10);
  uint16_t leg = 11;
  for (const double x : {-0.45, 0.45}) {
    for (const double y : {-0.45, 0.45}) {
      if (legs) scene.addBox({0.05f, 0.05f, 0.70f}, Eigen::Vector3d(x, y, 0.35), leg++);
    }
  }
  scene.addBox({0.1f, 0.1f, 0.45f}, Eigen::Vector3d(0, 0, 0.225), 30);
  return scene;
}

// Whether the post and the table top end in one object.
bool postJoinsTop(bool legs, float shadow_gap_m) {
  const Scene scene = tableOverPost(legs);
  GsmParams params;
  params.object_shadow_gap_m = shadow_gap_m;
  Gsm gsm = makeGsm(params);
  const auto label_of = scene.fuse(&gsm, Eigen::Vector3d(0, 0, 0.5), 16, 0.0, {}, 2.5);
  const ObjectGroups g = gsm.groupObjects();
  const Label top = objectOf(g, label_of, 10), post = objectOf(g, label_of, 30);
  EXPECT_NE(top, 0u);
  EXPECT_NE(post, 0u);
  return top == post;
}

TEST(Objects, APostUnderATableStandingOnItsLegsStaysItsOwnObject) {
  // The table stands on its legs: nothing unseen has to carry it, so no shadow joins anything
  // to it, however long the gap may be (as a chair pushed under a desk, its armrests a few
  // centimetres below the top).
  EXPECT_FALSE(postJoinsTop(true, GsmParams().object_shadow_gap_m));
  EXPECT_FALSE(postJoinsTop(true, 0.6f));
}

TEST(Objects, AFloatingTopJoinsThePostUnderItWithinTheShadowGapOnly) {
  // Without legs the top floats: the post must carry it, but 0.5 m of shadow is farther than
  // object_shadow_gap_m (0.3 m); at 0.6 m the probe from the post reaches the top.
  EXPECT_FALSE(postJoinsTop(false, GsmParams().object_shadow_gap_m));
  EXPECT_TRUE(postJoinsTop(false, 0.6f));
}

}  // namespace
}  // namespace objdb::gsm
