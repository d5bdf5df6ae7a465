// The Store conformance suite (store_conformance.h), part 2: sessions, scene maps, saved live
// maps and the bounded cache of decoded scene maps. Part 1: store_conformance_test.cpp.
#include <memory>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "tests/storage/store_conformance.h"
#include "tests/storage/store_fixtures.h"

namespace objdb::storage {
namespace {

using objdb::testing::diffLayers;
using objdb::testing::makeRawSegment;
using objdb::testing::makeStoreModel;
using objdb::testing::StoreConformance;
using objdb::testing::tableRows;
using ::testing::HasSubstr;

// Every voxel's main label for the blocks of `map`: 0 (none) for every `zero_every`-th voxel,
// else `base` plus a small offset.
gsm::LabelBlocks labelsFor(const tsdf::TsdfLayer& map, size_t zero_every, gsm::Label base) {
  gsm::LabelBlocks labels;
  for (const auto& [index, block] : map.blocks()) {
    std::vector<gsm::Label> l(block->voxels().size());
    for (size_t i = 0; i < l.size(); ++i) {
      l[i] = i % zero_every == 0 ? 0 : gsm::Label(base + index.x() + i % 3);
    }
    labels.emplace(index, std::move(l));
  }
  return labels;
}

// A one-block map, distinct per `seed`.
tsdf::TsdfLayer smallMap(int seed) {
  tsdf::TsdfLayer layer = tsdf::TsdfLayer::create(0.02f, 8).value();
  layer.allocateBlock({seed, 5, 5}).voxels()[size_t(seed)].weight = 1.0f + float(seed);
  return layer;
}

// Whether `store`'s saved map of `session` is `map` with `labels` after `frames` frames.
::testing::AssertionResult savedIs(const Store& store, const std::string& session, int64_t frames,
                                   const tsdf::TsdfLayer& map, const gsm::LabelBlocks& labels) {
  const auto saved = store.savedMap(session);
  if (!saved.ok()) return ::testing::AssertionFailure() << saved.status();
  if (saved->frames != frames) {
    return ::testing::AssertionFailure() << "frames " << saved->frames << ", expected " << frames;
  }
  if (saved->map == nullptr) return ::testing::AssertionFailure() << "no saved map";
  if (const std::string diff = diffLayers(*saved->map, map); !diff.empty()) {
    return ::testing::AssertionFailure() << diff;
  }
  if (saved->labels == nullptr || !(*saved->labels == labels)) {
    return ::testing::AssertionFailure() << "the labels differ";
  }
  return ::testing::AssertionSuccess();
}

TEST_P(StoreConformance, SessionsHaveALifecycle) {
  const std::string target = freshTarget();
  auto store = open(target);
  ASSERT_NE(store, nullptr);
  EXPECT_TRUE(store->sessions().value().empty());
  SessionInfo info;
  info.name = "monday";
  info.intrinsics_json = R"({"fx":525})";
  info.params_json = R"({"voxel_size_m":0.02})";
  const auto begun = store->beginSession(info);
  ASSERT_TRUE(begun.ok()) << begun.status();
  EXPECT_EQ(begun->name, "monday");
  EXPECT_EQ(begun->state, SessionState::kOpen);
  const auto duplicate = store->beginSession(info);
  EXPECT_EQ(duplicate.status().code(), absl::StatusCode::kAlreadyExists) << duplicate.status();
  EXPECT_THAT(duplicate.status().message(), HasSubstr("monday"));
  ASSERT_TRUE(store->putRawSegment(makeRawSegment("tuesday", 1, 1)).ok());  // implicit session
  SessionInfo later;
  later.name = "alpha";  // listed in creation order, not by name
  ASSERT_TRUE(store->beginSession(later).ok());
  ASSERT_TRUE(store->finishSession("monday", SessionState::kEnded, 300).ok());
  ASSERT_TRUE(store->finishSession("alpha", SessionState::kInterrupted, 12).ok());
  const Status unknown = store->finishSession("friday", SessionState::kEnded, 1);
  EXPECT_EQ(unknown.code(), absl::StatusCode::kNotFound) << unknown;
  EXPECT_THAT(unknown.message(), HasSubstr("friday"));
  store.reset();
  store = open(target);
  ASSERT_NE(store, nullptr);
  const auto sessions = store->sessions().value();
  ASSERT_EQ(sessions.size(), 3u);
  EXPECT_EQ(sessions[0].name, "monday");
  EXPECT_EQ(sessions[0].id, begun->id);
  EXPECT_EQ(sessions[0].state, SessionState::kEnded);
  EXPECT_EQ(sessions[0].frames, 300);
  EXPECT_EQ(sessions[0].intrinsics_json, info.intrinsics_json);
  EXPECT_EQ(sessions[0].params_json, info.params_json);
  EXPECT_FALSE(sessions[0].started_at.empty());
  EXPECT_FALSE(sessions[0].ended_at.empty());
  EXPECT_EQ(sessions[1].name, "tuesday");
  EXPECT_EQ(sessions[1].state, SessionState::kOpen);
  EXPECT_TRUE(sessions[1].ended_at.empty());
  EXPECT_EQ(sessions[2].name, "alpha");
  EXPECT_EQ(sessions[2].state, SessionState::kInterrupted);
  EXPECT_EQ(sessions[2].frames, 12);
  EXPECT_LT(sessions[0].id, sessions[1].id);
  EXPECT_LT(sessions[1].id, sessions[2].id);
  EXPECT_EQ(store->beginSession(info).status().code(), absl::StatusCode::kAlreadyExists)
      << "an ended session's name stays taken";
}

// Issue 47: a session's client and counters are kept (unknown, empty, until stored); a session's
// name is freed by retiring it: deleted when nothing refers to it, else renamed as a record.
TEST_P(StoreConformance, SessionsKeepClientAndCountersAndRetireByDeletionOrRenaming) {
  const std::string target = freshTarget();
  auto store = open(target);
  ASSERT_NE(store, nullptr);
  SessionInfo info;
  info.name = "monday";
  info.client_info = "objdb stream";
  ASSERT_TRUE(store->beginSession(info).ok());
  EXPECT_TRUE(store->sessions().value().front().counters_json.empty());  // unknown
  ASSERT_TRUE(store->storeSessionCounters("monday", R"({"frames_integrated":"12"})").ok());
  const Status unknown = store->storeSessionCounters("friday", "{}");
  EXPECT_EQ(unknown.code(), absl::StatusCode::kNotFound) << unknown;
  SessionInfo empty;
  empty.name = "empty";
  ASSERT_TRUE(store->beginSession(empty).ok());
  ASSERT_TRUE(store->putRawSegment(makeRawSegment("monday", 1, 1)).ok());
  ASSERT_TRUE(store->putSavedMap("monday", 4, smallMap(1), {}).ok());
  store.reset();
  store = open(target);
  ASSERT_NE(store, nullptr);
  auto sessions = store->sessions().value();
  ASSERT_EQ(sessions.size(), 2u);
  EXPECT_EQ(sessions[0].client_info, "objdb stream");
  EXPECT_EQ(sessions[0].counters_json, R"({"frames_integrated":"12"})");

  // Nothing refers to "empty": its row goes, and the name is free.
  EXPECT_TRUE(store->retireSession("empty", "empty.replaced-1").value());
  ASSERT_TRUE(store->beginSession(empty).ok());
  // A raw segment refers to "monday": renamed and interrupted, its segment and data kept under
  // the new name, its saved map dropped.
  const auto renamed = store->retireSession("monday", "monday.replaced-1");
  ASSERT_TRUE(renamed.ok()) << renamed.status();
  EXPECT_FALSE(*renamed);
  sessions = store->sessions().value();
  ASSERT_EQ(sessions.size(), 2u);
  EXPECT_EQ(sessions[0].name, "monday.replaced-1");
  EXPECT_EQ(sessions[0].state, SessionState::kInterrupted);
  EXPECT_FALSE(sessions[0].ended_at.empty());
  EXPECT_EQ(sessions[0].counters_json, R"({"frames_integrated":"12"})");
  EXPECT_EQ(store->savedMapFrames("monday.replaced-1").value(), -1);
  const auto kept = store->rawSegment({"monday.replaced-1", 1});
  EXPECT_TRUE(kept.ok() && *kept != nullptr) << kept.status();
  ASSERT_TRUE(store->beginSession(info).ok());  // the name is free
  ASSERT_TRUE(store->putRawSegment(makeRawSegment("monday", 2, 2)).ok());
  EXPECT_EQ(store->retireSession("monday", "monday.replaced-1").status().code(),
            absl::StatusCode::kAlreadyExists);  // a record of that name exists
  EXPECT_EQ(store->retireSession("friday", "x").status().code(), absl::StatusCode::kNotFound);
}

TEST_P(StoreConformance, ScenesRoundTripPerBlockAndSurviveReopen) {
  const std::string target = freshTarget();
  const model::ObjectModel m = makeStoreModel(9, 1);
  auto scene = std::make_shared<const tsdf::TsdfLayer>(m.grid.clone());
  {
    auto store = open(target);
    ASSERT_NE(store, nullptr);
    EXPECT_EQ(store->scene("monday").value(), nullptr);
    EXPECT_EQ(store->sceneLabels("monday").value(), nullptr);
    ASSERT_TRUE(store->putScene("monday", scene).ok());
    const Status null_scene = store->putScene("monday", nullptr);
    EXPECT_EQ(null_scene.code(), absl::StatusCode::kInvalidArgument) << null_scene;
    EXPECT_THAT(null_scene.message(), HasSubstr("monday"));
  }
  auto store = open(target);
  ASSERT_NE(store, nullptr);
  const auto loaded = store->scene("monday");
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  ASSERT_NE(*loaded, nullptr);
  EXPECT_EQ(diffLayers(**loaded, *scene), "");
  EXPECT_EQ(store->sceneLabels("monday").value(), nullptr);  // stored without labels
  // With labels: every voxel's main label, per block.
  auto labels = std::make_shared<const gsm::LabelBlocks>(labelsFor(*scene, 7, 40));
  ASSERT_TRUE(store->putScene("labelled", scene, labels).ok());
  auto wrong = std::make_shared<gsm::LabelBlocks>(*labels);
  wrong->begin()->second.pop_back();
  EXPECT_EQ(store->putScene("labelled", scene, wrong).code(), absl::StatusCode::kInvalidArgument);
  store.reset();
  store = open(target);
  ASSERT_NE(store, nullptr);
  const auto loaded_labels = store->sceneLabels("labelled");
  ASSERT_TRUE(loaded_labels.ok()) << loaded_labels.status();
  ASSERT_NE(*loaded_labels, nullptr);
  EXPECT_TRUE(**loaded_labels == *labels) << "the refused labels changed nothing";
  EXPECT_EQ(diffLayers(*store->scene("labelled").value(), *scene), "");
  // Replacing the scene replaces all its blocks.
  const tsdf::TsdfLayer smaller = smallMap(5);
  ASSERT_TRUE(store->putScene("monday", std::make_shared<const tsdf::TsdfLayer>(smaller.clone())).ok());
  store.reset();
  store = open(target);
  ASSERT_NE(store, nullptr);
  EXPECT_EQ(diffLayers(*store->scene("monday").value(), smaller), "");
  EXPECT_EQ(diffLayers(*store->scene("labelled").value(), *scene), "") << "other sessions kept";
}

// The server saves an open session's live map now and then (docs/server.md): it reads back
// whole, replaces the earlier save, is not the session's scene map, survives an interrupted end
// and is deleted when the session ends.
TEST_P(StoreConformance, SavedLiveMapsRoundTripStayApartFromScenesAndGoWhenTheSessionEnds) {
  const std::string target = freshTarget();
  const model::ObjectModel m = makeStoreModel(11, 1);
  const tsdf::TsdfLayer& map = m.grid;
  const gsm::LabelBlocks labels = labelsFor(map, 5, 7);
  auto store = open(target);
  ASSERT_NE(store, nullptr);
  SessionInfo info;
  info.name = "monday";
  ASSERT_TRUE(store->beginSession(info).ok());
  EXPECT_EQ(store->savedMap("monday").value().map, nullptr);
  EXPECT_EQ(store->savedMap("nobody").value().map, nullptr);
  EXPECT_EQ(store->savedMapFrames("monday").value(), -1);
  EXPECT_EQ(store->savedMapFrames("nobody").value(), -1);

  ASSERT_TRUE(store->putSavedMap("monday", 42, map, labels).ok());
  store.reset();
  store = open(target);
  ASSERT_NE(store, nullptr);
  {
    const auto saved = store->savedMap("monday");
    ASSERT_TRUE(saved.ok()) << saved.status();
    EXPECT_EQ(saved->frames, 42);
    ASSERT_NE(saved->map, nullptr);
    EXPECT_EQ(diffLayers(*saved->map, map), "");
    ASSERT_NE(saved->labels, nullptr);
    EXPECT_TRUE(*saved->labels == labels);
  }
  EXPECT_EQ(store->savedMapFrames("monday").value(), 42);
  EXPECT_EQ(store->scene("monday").value(), nullptr) << "a saved live map is not a scene map";
  EXPECT_EQ(store->sceneLabels("monday").value(), nullptr);
  const auto report = store->check();
  ASSERT_TRUE(report.ok()) << report.status();
  EXPECT_TRUE(report->ok());
  EXPECT_GE(report->blobs_checked, 2 * map.numBlocks());

  // A later save replaces every block of the earlier one.
  const tsdf::TsdfLayer smaller = smallMap(5);
  gsm::LabelBlocks smaller_labels;
  smaller_labels[{5, 5, 5}] = std::vector<gsm::Label>(smaller.block({5, 5, 5})->voxels().size(), 3);
  ASSERT_TRUE(store->putSavedMap("monday", 50, smaller, smaller_labels).ok());
  gsm::LabelBlocks wrong = smaller_labels;
  wrong.begin()->second.pop_back();
  EXPECT_EQ(store->putSavedMap("monday", 51, smaller, wrong).code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_TRUE(savedIs(*store, "monday", 50, smaller, smaller_labels));
  EXPECT_EQ(store->savedMapFrames("monday").value(), 50);
  // Dropped on request (another session's save stays).
  ASSERT_TRUE(store->putSavedMap("tuesday", 7, map, labels).ok());
  ASSERT_TRUE(store->dropSavedMap("tuesday").ok());
  EXPECT_EQ(store->savedMap("tuesday").value().map, nullptr);
  EXPECT_EQ(store->savedMapFrames("tuesday").value(), -1);
  EXPECT_EQ(store->savedMapFrames("monday").value(), 50);
  // Interrupted: kept, the session may still be ended from it. Ended: gone, with its rows.
  ASSERT_TRUE(store->finishSession("monday", SessionState::kInterrupted, 50).ok());
  EXPECT_NE(store->savedMap("monday").value().map, nullptr);
  ASSERT_TRUE(store->finishSession("monday", SessionState::kEnded, 50).ok());
  EXPECT_EQ(store->savedMap("monday").value().map, nullptr);
  EXPECT_EQ(store->savedMapFrames("monday").value(), -1);
  const StoreStats stats = store->stats().value();
  EXPECT_EQ(tableRows(stats, "saved_blocks"), 0);
  EXPECT_EQ(tableRows(stats, "saved_label_blocks"), 0);
}

// An incremental save (updateSavedMap) reads back as the whole new map: blocks shared with the
// base kept, changed and new blocks written, blocks the new map lacks deleted, label blocks
// likewise. Without a saved map to update, a store writes the whole map or refuses with
// FAILED_PRECONDITION and writes nothing.
TEST_P(StoreConformance, AnIncrementalSaveReadsBackAsTheWholeNewMap) {
  const std::string target = freshTarget();
  auto store = open(target);
  ASSERT_NE(store, nullptr);
  SessionInfo info;
  info.name = "monday";
  ASSERT_TRUE(store->beginSession(info).ok());

  // The live map, its first snapshot saved whole.
  tsdf::TsdfLayer live = tsdf::TsdfLayer::create(0.02f, 8).value();
  for (int b = 0; b < 4; ++b) {
    std::vector<tsdf::TsdfVoxel>& voxels = live.allocateBlock({b, -b, 2 * b}).voxels();
    for (size_t i = 0; i < voxels.size(); i += 3) {
      voxels[i].distance = 0.01f * float(int(i % 7) - 3);
      voxels[i].weight = 1.0f + float(b);
    }
  }
  const tsdf::TsdfLayer first = live.snapshot();
  const gsm::LabelBlocks first_labels = labelsFor(first, 5, 7);
  ASSERT_TRUE(store->putSavedMap("monday", 10, first, first_labels).ok());

  // Ten frames later: one block changed, one new; one label block changed, one gone.
  const tsdf::BlockIndex changed = first.blocks().begin()->first;
  live.block(changed)->voxels()[3].distance = 0.25f;
  live.block(changed)->voxels()[3].weight = 9.0f;
  live.allocateBlock({40, 41, 42}).voxels()[7].weight = 2.0f;
  const tsdf::TsdfLayer second = live.snapshot();
  gsm::LabelBlocks second_labels = labelsFor(second, 5, 7);
  second_labels[changed][1] = 99;
  second_labels.erase(std::next(first.blocks().begin())->first);
  const Status updated = store->updateSavedMap("monday", 20, second, second_labels, first,
                                               first_labels);
  ASSERT_TRUE(updated.ok()) << updated;
  EXPECT_TRUE(savedIs(*store, "monday", 20, second, second_labels));
  EXPECT_EQ(store->savedMapFrames("monday").value(), 20);

  // A new map lacking blocks of its base: those are deleted (here every block is another
  // object than the base's, so all are written again).
  tsdf::TsdfLayer third = smallMap(4);
  const gsm::LabelBlocks third_labels = labelsFor(third, 2, 1);
  ASSERT_TRUE(store->updateSavedMap("monday", 30, third, third_labels, second, second_labels).ok());
  EXPECT_TRUE(savedIs(*store, "monday", 30, third, third_labels));
  const auto report = store->check();
  ASSERT_TRUE(report.ok()) << report.status();
  EXPECT_TRUE(report->ok());

  // A label block of the wrong size: INVALID_ARGUMENT, the saved map unchanged.
  gsm::LabelBlocks wrong = third_labels;
  wrong.begin()->second.pop_back();
  EXPECT_EQ(store->updateSavedMap("monday", 31, third, wrong, third, third_labels).code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(store->savedMapFrames("monday").value(), 30);

  // Nothing saved to update: the whole map, or FAILED_PRECONDITION and nothing.
  info.name = "tuesday";
  ASSERT_TRUE(store->beginSession(info).ok());
  const Status fresh = store->updateSavedMap("tuesday", 5, second, second_labels, first,
                                             first_labels);
  if (fresh.ok()) {
    EXPECT_TRUE(savedIs(*store, "tuesday", 5, second, second_labels));
  } else {
    EXPECT_EQ(fresh.code(), absl::StatusCode::kFailedPrecondition) << fresh;
    EXPECT_EQ(store->savedMapFrames("tuesday").value(), -1);
  }
}

// The decoded-scene cache keeps the most recently used maps only: a long-lived server with many
// sessions does not keep every map in memory. Evicted maps are decoded again, unchanged.
TEST_P(StoreConformance, TheSceneCacheIsBoundedAndEvictedScenesReadBackUnchanged) {
  const std::string target = freshTarget();
  StoreOptions options;
  options.sqlite.max_cached_scenes = 2;
  options.postgres.max_cached_scenes = 2;
  auto store = open(target, options);
  ASSERT_NE(store, nullptr);
  std::vector<std::shared_ptr<const tsdf::TsdfLayer>> scenes;
  std::vector<std::shared_ptr<const gsm::LabelBlocks>> labels;
  for (int s = 0; s < 4; ++s) {
    scenes.push_back(std::make_shared<const tsdf::TsdfLayer>(smallMap(s)));
    labels.push_back(std::make_shared<const gsm::LabelBlocks>(labelsFor(*scenes.back(), 4, 10 + s)));
    ASSERT_TRUE(store->putScene("s" + std::to_string(s), scenes.back(), labels.back()).ok());
  }
  // Reads in an order that evicts and reloads each of them at least once.
  for (int s : {0, 3, 1, 0, 2, 3, 1}) {
    const std::string session = "s" + std::to_string(s);
    const auto loaded = store->scene(session);
    ASSERT_TRUE(loaded.ok()) << loaded.status();
    ASSERT_NE(*loaded, nullptr) << s;
    EXPECT_EQ(diffLayers(**loaded, *scenes[size_t(s)]), "") << s;
    const auto loaded_labels = store->sceneLabels(session);
    ASSERT_TRUE(loaded_labels.ok()) << loaded_labels.status();
    ASSERT_NE(*loaded_labels, nullptr) << s;
    EXPECT_TRUE(**loaded_labels == *labels[size_t(s)]) << s;
  }
  // The two most recent are served from memory: the very same object.
  EXPECT_EQ(store->scene("s1").value().get(), store->scene("s1").value().get());
  EXPECT_NE(store->scene("s0").value().get(), scenes[0].get()) << "s0 was evicted and decoded";
  store.reset();
  options.sqlite.max_cached_scenes = 0;
  options.postgres.max_cached_scenes = 0;
  const auto refused = storage::openStore(target, options);
  EXPECT_EQ(refused.status().code(), absl::StatusCode::kInvalidArgument) << refused.status();
  EXPECT_THAT(refused.status().message(), HasSubstr("max_cached_scenes"));
}

}  // namespace
}  // namespace objdb::storage
