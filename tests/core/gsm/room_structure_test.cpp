#include "core/gsm/room_structure.h"

#include <cmath>
#include <map>

#include <gtest/gtest.h>

#include "core/common/grid_key.h"
#include "core/gsm/gsm.h"
#include "core/gsm/objects.h"
#include "core/sim/shapes.h"
#include "tests/support/furniture_scene.h"

namespace objdb::gsm {
namespace {

using testing::FurnitureScene;

using testing::makeGsm;
using testing::objectOf;

// A corner of a room: the floor (1), two walls 2.4 m high (2: x = −1.6, facing +x; 3: y = 1.6,
// facing −y), a chair (10 … 15) in the middle, seen from cameras 1.2 m around it.
FurnitureScene roomCorner() {
  FurnitureScene scene;
  TriangleMesh wall_x = sim::makeBox({0.1f, 4.0f, 2.4f});
  scene.add(std::move(wall_x), Eigen::Vector3d(-1.35, 0, 1.2), 2);
  TriangleMesh wall_y = sim::makeBox({4.0f, 0.1f, 2.4f});
  scene.add(std::move(wall_y), Eigen::Vector3d(0, 1.35, 1.2), 3);
  scene.addChair(Eigen::Vector3d(0, 0, 0), 10);
  return scene;
}

void expectChairIsOneObjectOfTheRoom(const ObjectGroups& g,
                                     const std::map<uint16_t, Label>& label_of) {
  const Label chair = objectOf(g, label_of, 10);
  ASSERT_NE(chair, 0u);
  for (uint16_t id = 11; id <= 15; ++id) EXPECT_EQ(objectOf(g, label_of, id), chair) << id;
  EXPECT_EQ(g.members.at(chair).size(), 6u) << ::testing::PrintToString(g.members.at(chair))
                                             << " " << ::testing::PrintToString(label_of);
  EXPECT_FALSE(g.structure.contains(chair));
  for (const uint16_t id : {1, 2, 3}) {
    ASSERT_TRUE(label_of.count(id)) << id;
    EXPECT_TRUE(g.structure.contains(label_of.at(id))) << "instance " << id << " is structure";
  }
}

TEST(RoomStructure, TheFloorAndTwoWallsAreFoundAndNamedAndTheChairIsNotStructure) {
  const FurnitureScene scene = roomCorner();
  Gsm gsm = makeGsm();
  const auto label_of = scene.fuse(&gsm, Eigen::Vector3d(0, 0, 0.4), 16, 0.0, {}, 1.6, 1.2);
  const ObjectGroups g = gsm.groupObjects();
  const RoomStructure& room = g.room;
  SCOPED_TRACE(room.summary());
  ASSERT_TRUE(room.up_found);
  EXPECT_GT(room.up.z(), 0.99f);
  std::map<StructureKind, int> kinds;
  for (const RoomPlane& p : room.planes) ++kinds[p.kind];
  EXPECT_EQ(kinds[StructureKind::kFloor], 1);
  EXPECT_EQ(kinds[StructureKind::kWall], 2);
  for (const RoomPlane& p : room.planes) {
    if (p.kind == StructureKind::kFloor) {
      EXPECT_NEAR(p.offset_m, 0.0f, 0.02f);
    }
  }
  expectChairIsOneObjectOfTheRoom(g, label_of);
  // No voxel of the chair's seat or back is a barrier (legs end on the floor: their lowest
  // voxels may be).
  size_t seat_barrier = 0;
  for (const auto& [key, plane] : room.barrier) {
    const tsdf::VoxelIndex v = unpackGridKey(key);
    const Label l = gsm.mainLabel(v);
    if (l == label_of.at(10) || l == label_of.at(11)) ++seat_barrier;
  }
  EXPECT_EQ(seat_barrier, 0u);
}

TEST(RoomStructure, IsFoundTheSameWhenTheWorldsZIsNotUp) {
  // The same corner in a world whose y is up (and turned about it): the floor, the walls and
  // the chair come out the same; up is the world's y.
  FurnitureScene scene = roomCorner();
  Transform T = Transform::Identity();
  T.linear() = (Eigen::AngleAxisd(0.4, Eigen::Vector3d::UnitY()) *
                Eigen::AngleAxisd(-M_PI / 2, Eigen::Vector3d::UnitX()))
                   .toRotationMatrix();
  T.translation() = Eigen::Vector3d(3.0, 1.0, -2.0);
  scene.setWorld(T);
  Gsm gsm = makeGsm();
  const auto label_of = scene.fuse(&gsm, Eigen::Vector3d(0, 0, 0.4), 16, 0.0, {}, 1.6, 1.2);
  const ObjectGroups g = gsm.groupObjects();
  SCOPED_TRACE(g.room.summary());
  ASSERT_TRUE(g.room.up_found);
  EXPECT_GT(g.room.up.dot((T.linear() * Eigen::Vector3d::UnitZ()).cast<float>()), 0.99f);
  int floors = 0, walls = 0;
  for (const RoomPlane& p : g.room.planes) {
    floors += p.kind == StructureKind::kFloor ? 1 : 0;
    walls += p.kind == StructureKind::kWall ? 1 : 0;
  }
  EXPECT_EQ(floors, 1);
  EXPECT_EQ(walls, 2);
  expectChairIsOneObjectOfTheRoom(g, label_of);
  // Without an up hint (a map restored without its cameras) the barrier is the same.
  const ObjectGroups no_up = groupObjects(gsm.tsdf(), gsm.mainLabelBlocks(), GsmParams{});
  EXPECT_FALSE(no_up.room.up_found);
  EXPECT_EQ(no_up.room.barrier.size(), g.room.barrier.size());
  EXPECT_EQ(no_up.structure, g.structure);
}

TEST(RoomStructure, ADriftDoubledWallIsOneStructurePlane) {
  // The wall seen in two halves of the session from poses 3 cm apart along its normal: two
  // parallel sheets in the map. They are one plane of two sheets, and one structure plane.
  Gsm gsm = makeGsm();
  FurnitureScene first, second;
  first.add(sim::makeBox({0.1f, 4.0f, 2.4f}), Eigen::Vector3d(-1.65, 0, 1.2), 2);
  second.add(sim::makeBox({0.1f, 4.0f, 2.4f}), Eigen::Vector3d(-1.62, 0, 1.2), 2);
  // Each half sees the wall from its own side of the room's middle (the sheets overlap).
  first.fuse(&gsm, Eigen::Vector3d(0, 0.3, 0.4), 16, 0.0, {}, 1.6, 1.2);
  second.fuse(&gsm, Eigen::Vector3d(0, -0.3, 0.4), 16, 0.2, {}, 1.6, 1.2);
  const ObjectGroups g = gsm.groupObjects();
  SCOPED_TRACE(g.room.summary());
  int wall_planes = 0;
  for (const RoomPlane& p : g.room.planes) {
    if (std::abs(p.normal.x()) > 0.9f && p.kind != StructureKind::kNone) {
      ++wall_planes;
      EXPECT_GT(p.offset_m, -1.62f);
      EXPECT_LT(p.offset_m, -1.54f);
    }
  }
  EXPECT_EQ(wall_planes, 1);
}

TEST(RoomStructure, AnEmptyMapAndASingleObjectWithoutAFloorHaveNone) {
  {
    Gsm gsm = makeGsm();
    const ObjectGroups g = gsm.groupObjects();
    EXPECT_FALSE(g.room.up_found);
    EXPECT_TRUE(g.room.planes.empty());
    EXPECT_TRUE(g.members.empty());
    EXPECT_NE(g.room.summary().find("no up direction"), std::string::npos);
  }
  // A chair on a small table top (no floor in view): the chair is one object, nothing is
  // structure.
  FurnitureScene scene;
  scene.addChair(Eigen::Vector3d(0, 0, 0), 10);
  Gsm gsm = makeGsm();
  const auto label_of = scene.fuse(&gsm, Eigen::Vector3d(0, 0, 0.4), 16, 0.0,
                                   {10, 11, 12, 13, 14, 15});
  const ObjectGroups g = gsm.groupObjects();
  SCOPED_TRACE(g.room.summary());
  const Label chair = objectOf(g, label_of, 10);
  ASSERT_NE(chair, 0u);
  EXPECT_EQ(g.members.at(chair).size(), 6u);
  EXPECT_TRUE(g.structure.empty());
}

// A bench of four boxes 0.8 m long in a row, each touching the next: 3.2 m, bigger than any
// furniture. Without a floor to say what stands (the floor carries no label), every contact
// connects and the whole falls back to its four parts; allowed 4 m, it is one object. With the
// floor, each box stands by itself and they stay apart without the fallback.
TEST(RoomStructure, AThreeMetreObjectFallsBackToItsParts) {
  FurnitureScene scene;
  for (int i = 0; i < 4; ++i) {
    scene.addBox({0.8f, 0.4f, 0.4f}, Eigen::Vector3d(-1.2 + 0.8 * i, 0, 0.25), uint16_t(10 + i));
  }
  GsmParams params;
  Gsm gsm = makeGsm(params);
  const auto label_of = scene.fuse(&gsm, Eigen::Vector3d(0, 0, 0.3), 16, 0.0, {10, 11, 12, 13}, 2.0);
  const ObjectGroups g = gsm.groupObjects();
  EXPECT_EQ(g.giant_fallbacks, 1u);
  std::set<Label> objects;
  for (uint16_t id = 10; id < 14; ++id) objects.insert(objectOf(g, label_of, id));
  EXPECT_EQ(objects.size(), 4u) << "every box its own object";
  params.object_max_extent_m = 4.0f;
  const ObjectGroups allowed = groupObjects(gsm.tsdf(), gsm.mainLabelBlocks(), params);
  EXPECT_EQ(allowed.giant_fallbacks, 0u);
  std::set<Label> one;
  for (uint16_t id = 10; id < 14; ++id) {
    one.insert(allowed.object_of.at(label_of.at(id)));
  }
  EXPECT_EQ(one.size(), 1u);

  Gsm with_floor = makeGsm();
  const auto labelled = scene.fuse(&with_floor, Eigen::Vector3d(0, 0, 0.3), 16, 0.0, {}, 2.0);
  const ObjectGroups standing = with_floor.groupObjects();
  EXPECT_EQ(standing.giant_fallbacks, 0u);
  EXPECT_GE(standing.standing_cuts, 3u);
  std::set<Label> apart;
  for (uint16_t id = 10; id < 14; ++id) apart.insert(objectOf(standing, labelled, id));
  EXPECT_EQ(apart.size(), 4u);
}

TEST(RoomStructure, RestoredFromTheSavedMapEqualsTheLiveOne) {
  const FurnitureScene scene = roomCorner();
  Gsm gsm = makeGsm();
  scene.fuse(&gsm, Eigen::Vector3d(0, 0, 0.4), 16, 0.0, {}, 1.6, 1.2);
  const ObjectGroups live = gsm.groupObjects();
  // A saved map keeps the TSDF and the main labels: a copy through them.
  const tsdf::TsdfLayer restored = gsm.tsdf().clone();
  const LabelBlocks labels = gsm.mainLabelBlocks();
  const ObjectGroups again = groupObjects(restored, labels, GsmParams{}, gsm.upHint());
  EXPECT_EQ(again.room.summary().substr(0, 40), live.room.summary().substr(0, 40));
  EXPECT_EQ(again.room.barrier, live.room.barrier);
  EXPECT_EQ(again.structure, live.structure);
  EXPECT_EQ(again.members, live.members);
  EXPECT_EQ(again.cut, live.cut);
}

}  // namespace
}  // namespace objdb::gsm
