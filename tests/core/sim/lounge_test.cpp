#include "core/sim/lounge.h"

#include <map>
#include <set>

#include <gtest/gtest.h>

#include "core/io/objdb_dataset.h"
#include "core/sim/generator.h"
#include "tests/support/temp_dir.h"

namespace objdb::sim {
namespace {

TEST(Lounge, HasThreeSessionsWithSeventeenObjectsOfElevenKinds) {
  auto sessions = loungePreset();
  ASSERT_TRUE(sessions.ok()) << sessions.status();
  ASSERT_EQ(sessions->size(), 3u);
  std::map<int, std::string> kind_of;
  for (const auto& s : *sessions) {
    EXPECT_TRUE(s.validate().ok());
    EXPECT_GE(s.trajectory.frames, 150);
    EXPECT_LE(s.trajectory.frames, 400);
    for (const auto& o : s.objects) {
      if (o.category == "wall") continue;
      auto [it, inserted] = kind_of.emplace(o.id, o.category);
      EXPECT_EQ(it->second, o.category) << "id " << o.id << " changes kind between sessions";
    }
  }
  std::map<std::string, int> count;
  for (const auto& [id, kind] : kind_of) ++count[kind];
  const std::map<std::string, int> expected = {
      {"cow", 1},         {"round_chair", 3},  {"cube_chair", 1},   {"fire_extinguisher", 3},
      {"gas_cylinder", 2}, {"helmet", 2},      {"round_table", 1},  {"square_table", 1},
      {"large_box", 1},   {"small_container", 1}, {"floor", 1}};
  EXPECT_EQ(count, expected);
  EXPECT_EQ(kind_of.size(), 17u);
}

TEST(Lounge, ObjectsAreMovedRemovedAndAddedBetweenSessions) {
  auto sessions = loungePreset();
  ASSERT_TRUE(sessions.ok());
  auto ids = [](const Scene& s) {
    std::map<int, Transform> m;
    for (const auto& o : s.objects) m[o.id] = o.T_world_object;
    return m;
  };
  const auto a = ids((*sessions)[0]), b = ids((*sessions)[1]);
  int moved = 0, removed = 0, added = 0;
  for (const auto& [id, T] : a) {
    if (!b.count(id)) {
      ++removed;
    } else if (!T.isApprox(b.at(id), 1e-6)) {
      ++moved;
    }
  }
  for (const auto& [id, T] : b) added += a.count(id) ? 0 : 1;
  EXPECT_GE(moved, 3);
  EXPECT_GE(removed, 1);
  EXPECT_GE(added, 1);
}

TEST(Lounge, ObjectsOnTheFloorDoNotIntersect) {
  auto sessions = loungePreset();
  ASSERT_TRUE(sessions.ok());
  for (const auto& s : *sessions) {
    auto built = buildScene(s);
    ASSERT_TRUE(built.ok());
    for (size_t i = 0; i < s.objects.size(); ++i) {
      const auto& a = s.objects[i];
      if (a.structure) continue;
      Eigen::Vector3f lo, hi;
      built->instances[i].mesh->bounds(&lo, &hi);
      const double ra = lo.head<2>().cwiseAbs().cwiseMax(hi.head<2>().cwiseAbs()).norm();
      const Eigen::Vector3d pa = a.T_world_object.translation();
      // Inside the 7 × 5 m room.
      EXPECT_GT(pa.x() - 0.9 * ra, 0.0) << s.name << " object " << a.id;
      EXPECT_LT(pa.x() + 0.9 * ra, 7.0) << s.name << " object " << a.id;
      EXPECT_GT(pa.y() - 0.9 * ra, 0.0) << s.name << " object " << a.id;
      EXPECT_LT(pa.y() + 0.9 * ra, 5.0) << s.name << " object " << a.id;
      for (size_t j = i + 1; j < s.objects.size(); ++j) {
        const auto& b = s.objects[j];
        if (b.structure) continue;
        const Eigen::Vector3d pb = b.T_world_object.translation();
        if (std::abs(pa.z() - pb.z()) > 0.1) continue;  // one stands on a table
        built->instances[j].mesh->bounds(&lo, &hi);
        const double rb = lo.head<2>().cwiseAbs().cwiseMax(hi.head<2>().cwiseAbs()).norm();
        // Bounding circles are generous for boxes: allow 15 % overlap of the radii.
        EXPECT_GT((pa - pb).head<2>().norm(), 0.85 * (ra + rb))
            << s.name << ": objects " << a.id << " and " << b.id << " intersect";
      }
    }
  }
}

TEST(Lounge, EveryObjectIsVisibleInAtLeastTwentyFramesOfSomeSession) {
  LoungeOptions options;
  options.noise = false;
  auto sessions = loungePreset(options);
  ASSERT_TRUE(sessions.ok());
  std::map<int, int> best;
  std::map<int, int> sessions_seen;
  for (const auto& s : *sessions) {
    auto built = buildScene(s);
    ASSERT_TRUE(built.ok());
    auto poses = sampleTrajectory(s.trajectory);
    ASSERT_TRUE(poses.ok());
    RenderParams params;
    params.render_color = false;
    const Renderer renderer(s.intrinsics, params);
    const int min_pixels = s.intrinsics.width * s.intrinsics.height / 200;
    std::map<int, int> visible;
    RenderOutput out;
    for (const auto& T : *poses) {
      renderer.render(built->instances, T, &out);
      std::map<int, int> pixels;
      for (uint16_t id : out.instances.data) ++pixels[id];
      for (const auto& [id, n] : pixels) visible[id] += (id != 0 && n >= min_pixels);
    }
    for (const auto& o : s.objects) {
      best[o.id] = std::max(best[o.id], visible[o.id]);
      sessions_seen[o.id] += visible[o.id] >= 20;
    }
  }
  for (const auto& [id, frames] : best) {
    std::printf("object %d: visible in %d frames of its best session\n", id, frames);
    EXPECT_GE(frames, 20) << "object " << id << " is visible in " << frames << " frames at most";
  }
  EXPECT_EQ(best.size(), 17u + 4u);  // 17 objects + 4 walls
}

TEST(Generator, WritesADatasetTheReaderReadsBackDeterministically) {
  testing::TempDir dir;
  Scene scene = twoBoxesScene("tango", 4);
  auto stats = generateDataset(scene, dir / "a");
  ASSERT_TRUE(stats.ok()) << stats.status();
  EXPECT_EQ(stats->frames, 4u);
  EXPECT_EQ(stats->frames_visible.at(1), 4);
  auto again = generateDataset(scene, dir / "b");
  ASSERT_TRUE(again.ok());

  auto a = io::ObjdbDataset::open(dir / "a");
  auto b = io::ObjdbDataset::open(dir / "b");
  ASSERT_TRUE(a.ok()) << a.status();
  ASSERT_TRUE(b.ok());
  ASSERT_EQ((*a)->size(), 4u);
  EXPECT_EQ((*a)->intrinsics(), Intrinsics::tango());
  ASSERT_EQ((*a)->objects().size(), 3u);
  EXPECT_EQ((*a)->objects()[0].category, "large_box");
  EXPECT_TRUE((*a)->objects()[2].is_structure);
  for (size_t i = 0; i < 4; ++i) {
    auto fa = (*a)->loadFrame(i);
    auto fb = (*b)->loadFrame(i);
    ASSERT_TRUE(fa.ok()) << fa.status();
    ASSERT_TRUE(fb.ok());
    EXPECT_EQ(fa->depth, fb->depth);  // same seed → identical output
    ASSERT_TRUE(fa->instances.has_value());
    ASSERT_TRUE(fa->color.has_value());
    EXPECT_EQ(*fa->instances, *fb->instances);
  }
  // Writing into an existing dataset is refused unless asked to overwrite.
  EXPECT_FALSE(generateDataset(scene, dir / "a").ok());
  GenerateOptions overwrite;
  overwrite.overwrite = true;
  EXPECT_TRUE(generateDataset(scene, dir / "a", overwrite).ok());
  // The scene file written beside the data renders the same world.
  auto reloaded = loadSceneFile(dir / "a" / "scene.json");
  ASSERT_TRUE(reloaded.ok()) << reloaded.status();
  EXPECT_EQ(reloaded->objects.size(), scene.objects.size());
}

TEST(Generator, RenderedDepthMatchesGroundTruthWithinTheNoise) {
  Scene scene = twoBoxesScene("vga", 3);
  auto built = buildScene(scene);
  ASSERT_TRUE(built.ok());
  auto poses = sampleTrajectory(scene.trajectory);
  ASSERT_TRUE(poses.ok());
  const Renderer renderer(scene.intrinsics);
  const Frame noisy = renderFrame(scene, *built, renderer, (*poses)[1], 1, false);
  scene.noise.enabled = false;
  const Frame clean = renderFrame(scene, *built, renderer, (*poses)[1], 1, false);
  size_t valid = 0, within = 0;
  for (size_t i = 0; i < clean.depth.size(); ++i) {
    if (!isValidDepth(noisy.depth.data[i])) continue;
    ++valid;
    const float z = clean.depth.data[i];
    within += std::abs(noisy.depth.data[i] - z) <= 4 * scene.noise.sigmaAt(z) + 0.001f;
  }
  EXPECT_GT(valid, clean.depth.size() / 2);
  EXPECT_GT(double(within) / valid, 0.999);
}

}  // namespace
}  // namespace objdb::sim
