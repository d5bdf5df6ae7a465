#include "core/tsdf/tsdf_layer.h"

#include <atomic>
#include <cmath>
#include <random>
#include <thread>

#include <gtest/gtest.h>

namespace objdb::tsdf {
namespace {

TEST(TsdfLayer, CreateRejectsAbsurdSizesNamingThem) {
  for (float size : {0.0f, -0.01f, 2.0f, std::nanf("")}) {
    auto layer = TsdfLayer::create(size, 8);
    ASSERT_FALSE(layer.ok()) << size;
    EXPECT_NE(layer.status().message().find("voxel size"), absl::string_view::npos);
  }
  EXPECT_FALSE(TsdfLayer::create(0.02f, 1).ok());
  EXPECT_FALSE(TsdfLayer::create(0.02f, 100).ok());
  EXPECT_TRUE(TsdfLayer::create(0.02f, 8).ok());
}

TEST(TsdfLayer, IndicesAreFloorBasedIncludingNegativeCoordinates) {
  TsdfLayer layer = TsdfLayer::create(0.1f, 4).value();
  EXPECT_EQ(layer.blockIndexOf({0.05f, 0.39f, 0.41f}), BlockIndex(0, 0, 1));
  EXPECT_EQ(layer.blockIndexOf({-0.01f, -0.4f, -0.41f}), BlockIndex(-1, -1, -2));
  EXPECT_EQ(layer.voxelIndexOf({-0.01f, 0.0f, 0.25f}), VoxelIndex(-1, 0, 2));
  EXPECT_EQ(layer.blockOfVoxel({-1, -4, -5}), BlockIndex(-1, -1, -2));
  EXPECT_EQ(layer.blockOfVoxel({3, 4, 0}), BlockIndex(0, 1, 0));
  // Every voxel of a block maps to a distinct slot.
  std::vector<int> seen(64, 0);
  for (int z = -4; z < 0; ++z) {
    for (int y = -4; y < 0; ++y) {
      for (int x = -4; x < 0; ++x) ++seen[layer.linearInBlock({x, y, z})];
    }
  }
  for (int count : seen) EXPECT_EQ(count, 1);
  EXPECT_TRUE(layer.voxelCenter({-1, 0, 2}).isApprox(Eigen::Vector3f(-0.05f, 0.05f, 0.25f)));
}

TEST(TsdfLayer, AllocationAndLookup) {
  TsdfLayer layer = TsdfLayer::create(0.02f, 8).value();
  EXPECT_EQ(layer.voxel({1, 2, 3}), nullptr);
  layer.allocateBlock({0, 0, 0});
  ASSERT_NE(layer.voxel({1, 2, 3}), nullptr);
  layer.voxel({1, 2, 3})->distance = 0.5f;
  EXPECT_EQ(layer.block({0, 0, 0})->voxel(1 + 8 * (2 + 8 * 3)).distance, 0.5f);
  layer.allocateBlock({0, 0, 0});  // allocating again keeps the data
  EXPECT_EQ(layer.voxel({1, 2, 3})->distance, 0.5f);
  EXPECT_EQ(layer.numBlocks(), 1u);
  EXPECT_EQ(layer.voxelBytes(), 512u * sizeof(TsdfVoxel));
}

TEST(TsdfLayer, TrilinearInterpolationIsExactOnLinearFields) {
  TsdfLayer layer = TsdfLayer::create(0.05f, 4).value();
  const Eigen::Vector3f g(0.3f, -0.7f, 0.2f);
  const float offset = 0.1f;
  for (int bz = -1; bz <= 1; ++bz) {
    for (int by = -1; by <= 1; ++by) {
      for (int bx = -1; bx <= 1; ++bx) layer.allocateBlock({bx, by, bz});
    }
  }
  for (const auto& [index, block] : layer.blocks()) {
    for (int z = 0; z < 4; ++z) {
      for (int y = 0; y < 4; ++y) {
        for (int x = 0; x < 4; ++x) {
          const VoxelIndex v = index * 4 + Eigen::Vector3i(x, y, z);
          TsdfVoxel* voxel = layer.voxel(v);
          voxel->distance = g.dot(layer.voxelCenter(v)) + offset;
          voxel->weight = 1.0f;
        }
      }
    }
  }
  std::mt19937 rng(4);
  std::uniform_real_distribution<float> coord(-0.17f, 0.17f);  // inside the centres' hull
  for (int i = 0; i < 1000; ++i) {
    const Eigen::Vector3f p(coord(rng), coord(rng), coord(rng));
    float d = 0.0f;
    ASSERT_TRUE(layer.interpolateDistance(p, &d)) << p.transpose();
    ASSERT_NEAR(d, g.dot(p) + offset, 1e-5f);
  }
  float d = 0.0f;
  EXPECT_FALSE(layer.interpolateDistance({1.0f, 1.0f, 1.0f}, &d));  // no blocks there
  layer.voxel({0, 0, 0})->weight = 0.0f;  // an unobserved corner
  EXPECT_FALSE(layer.interpolateDistance({0.03f, 0.03f, 0.03f}, &d));
}

TEST(TsdfLayer, ASnapshotSharesBlocksAndNeverSeesLaterWrites) {
  TsdfLayer layer = TsdfLayer::create(0.1f, 4).value();
  for (int x = 0; x < 3; ++x) layer.allocateBlock({x, 0, 0}).voxel(0).distance = float(x);
  const TsdfLayer snap = layer.snapshot();
  EXPECT_EQ(snap.numBlocks(), 3u);
  EXPECT_EQ(layer.numSharedBlocks(), 3u);  // no voxel copied yet
  // Writes through every mutable path: the written block is copied first, the others stay shared.
  layer.block({0, 0, 0})->voxel(0).distance = 10.0f;
  layer.voxel({4, 0, 0})->distance = 11.0f;          // block (1, 0, 0)
  layer.allocateBlock({3, 0, 0}).voxel(0).distance = 12.0f;  // new block: not in the snapshot
  EXPECT_EQ(layer.numSharedBlocks(), 1u);  // block (2, 0, 0) only
  EXPECT_EQ(snap.block({0, 0, 0})->voxel(0).distance, 0.0f);
  EXPECT_EQ(snap.block({1, 0, 0})->voxel(0).distance, 1.0f);
  EXPECT_EQ(snap.block({3, 0, 0}), nullptr);
  EXPECT_EQ(layer.block({0, 0, 0})->voxel(0).distance, 10.0f);
  EXPECT_EQ(layer.block({1, 0, 0})->voxel(0).distance, 11.0f);
  // A block the layer writes again after the snapshot is gone is written in place.
  const TsdfBlock* before = &*layer.blocks().at(BlockIndex(0, 0, 0));
  layer.block({0, 0, 0})->voxel(1).distance = 5.0f;
  EXPECT_EQ(&*layer.blocks().at(BlockIndex(0, 0, 0)), before);
}

TEST(TsdfLayer, AllocateBlocksCreatesCopiesSharedAndKeepsOwnBlocksOnAnyThreadCount) {
  for (int threads : {1, 2, 4}) {
    TsdfLayer layer = TsdfLayer::create(0.1f, 4).value();
    // 200 blocks before the snapshot (enough for the threads to be used), 100 only after it.
    for (int x = 0; x < 200; ++x) layer.allocateBlock({x, 1, 0}).voxel(0).distance = float(x);
    const TsdfLayer snap = layer.snapshot();
    layer.allocateBlock({0, 1, 0});  // unshared again before the batch: written in place below
    const TsdfBlock* own = &*layer.blocks().at(BlockIndex(0, 1, 0));
    std::vector<BlockIndex> indices;
    for (int x = 0; x < 300; ++x) indices.emplace_back(x, 1, 0);
    WorkerPool pool(threads);
    const std::vector<TsdfBlock*> blocks = layer.allocateBlocks(indices, &pool);
    ASSERT_EQ(blocks.size(), indices.size());
    EXPECT_EQ(layer.numBlocks(), 300u);
    EXPECT_EQ(layer.numSharedBlocks(), 0u) << threads;
    EXPECT_EQ(blocks[0], own);
    for (int x = 0; x < 300; ++x) {
      ASSERT_EQ(blocks[size_t(x)], layer.block(indices[size_t(x)])) << x;
      // Copies keep the values; new blocks are unobserved.
      ASSERT_EQ(blocks[size_t(x)]->voxel(0).distance, x < 200 ? float(x) : 0.0f) << x;
      ASSERT_EQ(blocks[size_t(x)]->voxel(0).weight, 0.0f);
      blocks[size_t(x)]->voxel(0).distance = -1.0f;
    }
    for (int x = 1; x < 200; ++x) {
      ASSERT_EQ(snap.block({x, 1, 0})->voxel(0).distance, float(x)) << "snapshot changed at " << x;
    }
    EXPECT_EQ(snap.block({250, 1, 0}), nullptr);
  }
}

TEST(TsdfLayer, ASnapshotReadOnAnotherThreadKeepsItsValuesWhileTheLayerIsWritten) {
  TsdfLayer layer = TsdfLayer::create(0.1f, 8).value();
  for (int x = 0; x < 64; ++x) {
    for (auto& v : layer.allocateBlock({x, 0, 0}).voxels()) v.distance = 1.0f;
  }
  auto snap = std::make_shared<const TsdfLayer>(layer.snapshot());
  std::atomic<bool> changed{false};
  std::thread reader([snap, &changed] {
    for (int round = 0; round < 200; ++round) {
      for (const auto& [index, block] : snap->blocks()) {
        for (const auto& v : block->voxels()) {
          if (v.distance != 1.0f) changed = true;
        }
      }
    }
  });
  for (int round = 0; round < 50; ++round) {
    for (int x = 0; x < 64; ++x) {
      for (auto& v : layer.block({x, 0, 0})->voxels()) v.distance = float(round + 2);
    }
  }
  reader.join();
  EXPECT_FALSE(changed);
  EXPECT_EQ(layer.block({5, 0, 0})->voxel(3).distance, 51.0f);
}

}  // namespace
}  // namespace objdb::tsdf
