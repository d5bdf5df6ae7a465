#include "storage/sqlite/sqlite_store.h"

#include <fstream>
#include <sstream>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <sqlite3.h>

#include "tests/storage/store_fixtures.h"
#include "tests/support/temp_dir.h"

namespace objdb::storage {
namespace {

using objdb::testing::diffLayers;
using objdb::testing::diffModels;
using objdb::testing::makeRawSegment;
using objdb::testing::makeStoreModel;
using objdb::testing::TempDir;
using ::testing::HasSubstr;

std::string readFile(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// Raw SQL on the file, outside the store (to damage it the way a disk or a person would).
void rawSql(const std::filesystem::path& path, const std::string& sql) {
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
  char* error = nullptr;
  EXPECT_EQ(sqlite3_exec(db, sql.c_str(), nullptr, nullptr, &error), SQLITE_OK)
      << (error ? error : "");
  sqlite3_free(error);
  sqlite3_close(db);
}

// Flips one byte in the middle of a blob column of one row.
void flipBlobByte(const std::filesystem::path& path, const std::string& table,
                  const std::string& column, int64_t rowid) {
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
  sqlite3_stmt* s = nullptr;
  const std::string select = "SELECT " + column + " FROM " + table + " WHERE rowid = ?";
  ASSERT_EQ(sqlite3_prepare_v2(db, select.c_str(), -1, &s, nullptr), SQLITE_OK);
  sqlite3_bind_int64(s, 1, rowid);
  ASSERT_EQ(sqlite3_step(s), SQLITE_ROW);
  std::string blob(static_cast<const char*>(sqlite3_column_blob(s, 0)),
                   size_t(sqlite3_column_bytes(s, 0)));
  sqlite3_finalize(s);
  blob[blob.size() - blob.size() / 3] ^= 0x01;
  const std::string update = "UPDATE " + table + " SET " + column + " = ? WHERE rowid = ?";
  ASSERT_EQ(sqlite3_prepare_v2(db, update.c_str(), -1, &s, nullptr), SQLITE_OK);
  sqlite3_bind_blob(s, 1, blob.data(), int(blob.size()), SQLITE_TRANSIENT);
  sqlite3_bind_int64(s, 2, rowid);
  ASSERT_EQ(sqlite3_step(s), SQLITE_DONE);
  sqlite3_finalize(s);
  sqlite3_close(db);
}

std::unique_ptr<SqliteStore> openStore(const std::filesystem::path& path,
                                       SqliteStoreOptions options = {}) {
  auto store = SqliteStore::open(path.string(), options);
  EXPECT_TRUE(store.ok()) << store.status();
  return store.ok() ? std::move(*store) : nullptr;
}

TEST(SqliteStore, ANewFileGetsTheCurrentSchemaInWalMode) {
  TempDir dir;
  auto store = openStore(dir / "db.sqlite");
  ASSERT_NE(store, nullptr);
  EXPECT_TRUE(store->schema().created);
  EXPECT_EQ(store->schema().version_after, currentSchemaVersion());
  EXPECT_TRUE(store->modelIds().value().empty());
  store.reset();
  // Journal mode is persistent in the file.
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open((dir / "db.sqlite").c_str(), &db), SQLITE_OK);
  sqlite3_stmt* s = nullptr;
  ASSERT_EQ(sqlite3_prepare_v2(db, "PRAGMA journal_mode", -1, &s, nullptr), SQLITE_OK);
  ASSERT_EQ(sqlite3_step(s), SQLITE_ROW);
  EXPECT_STREQ(reinterpret_cast<const char*>(sqlite3_column_text(s, 0)), "wal");
  sqlite3_finalize(s);
  sqlite3_close(db);
}

TEST(SqliteStore, ModelsRoundTripBitExactAcrossReopen) {
  TempDir dir;
  std::vector<model::ObjectModel> originals;
  {
    auto store = openStore(dir / "db.sqlite");
    for (uint32_t seed : {1u, 2u, 5u}) {
      model::ObjectModel m = makeStoreModel(seed, int(seed % 3) + 1);
      const auto id = store->addModel(model::cloneModel(m));
      ASSERT_TRUE(id.ok()) << id.status();
      m.id = *id;
      originals.push_back(std::move(m));
    }
    EXPECT_EQ(originals[0].id, 1);
    EXPECT_EQ(originals[2].id, 3);
  }
  auto store = openStore(dir / "db.sqlite");
  EXPECT_FALSE(store->schema().created);
  EXPECT_EQ(store->modelIds().value(), (std::vector<int64_t>{1, 2, 3}));
  for (const auto& m : originals) {
    const auto loaded = store->model(m.id);
    ASSERT_TRUE(loaded.ok()) << loaded.status();
    EXPECT_EQ(diffModels(**loaded, m), "") << "model " << m.id;
  }
  const auto entries = store->matchEntries().value();
  ASSERT_EQ(entries.entries.size(), 3u);
  EXPECT_TRUE(entries.skipped.empty());
  EXPECT_EQ(entries.entries[1].descriptors, originals[1].descriptors);
  EXPECT_EQ(entries.entries[1].num_points, originals[1].cloud.points.size());
  ASSERT_EQ(entries.entries[2].segments.size(), originals[2].observations.size());
  EXPECT_EQ(entries.entries[2].segments[1].session, "s1");
  EXPECT_EQ(entries.entries[2].planar, originals[2].planar);
}

TEST(SqliteStore, ReplaceAndRemoveKeepIdsStableAndNeverReuseThem) {
  TempDir dir;
  auto store = openStore(dir / "db.sqlite");
  const int64_t a = store->addModel(makeStoreModel(1, 1)).value();
  const int64_t b = store->addModel(makeStoreModel(2, 1)).value();
  model::ObjectModel merged = makeStoreModel(3, 2);
  merged.id = a;
  database::MergeRecord record;
  record.target = a;
  record.source = "segment s1/7";
  record.T_target_source = merged.observations[1].T_object_segment;
  record.icp_rmse_m = 0.0125;
  record.tsdf_rmse_m = 0.0061;
  record.tsdf_overlap = 12345;
  record.scene_checks = 2;
  ASSERT_TRUE(store->replaceModel(model::cloneModel(merged), record).ok());
  EXPECT_EQ(diffModels(*store->model(a).value(), merged), "");
  const auto records = store->mergeRecords().value();
  ASSERT_EQ(records.size(), 1u);
  EXPECT_EQ(records[0].source, "segment s1/7");
  EXPECT_TRUE(records[0].T_target_source.matrix() == record.T_target_source.matrix());
  EXPECT_EQ(records[0].tsdf_overlap, 12345u);
  EXPECT_EQ(records[0].icp_rmse_m, 0.0125);

  ASSERT_TRUE(store->removeModel(b).ok());
  EXPECT_EQ(store->model(b).status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(store->removeModel(b).code(), absl::StatusCode::kNotFound);
  model::ObjectModel ghost = makeStoreModel(4, 1);
  ghost.id = b;
  EXPECT_EQ(store->replaceModel(std::move(ghost), std::nullopt).code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(store->addModel(makeStoreModel(5, 1)).value(), 3);  // b = 2 is not reused
  store.reset();
  store = openStore(dir / "db.sqlite");
  EXPECT_EQ(store->addModel(makeStoreModel(6, 1)).value(), 4);
  EXPECT_EQ(store->modelIds().value(), (std::vector<int64_t>{1, 3, 4}));
  const auto stats = store->stats().value();
  EXPECT_EQ(stats.active_models, 3);
  EXPECT_EQ(stats.removed_models, 1);
}

TEST(SqliteStore, AnAbsorbedModelIsKeptAsMergedIntoItsTargetInOneUnit) {
  TempDir dir;
  auto store = openStore(dir / "db.sqlite");
  const int64_t a = store->addModel(makeStoreModel(1, 1)).value();
  const int64_t b = store->addModel(makeStoreModel(2, 1)).value();
  model::ObjectModel joined = makeStoreModel(3, 2);  // both models' observations
  joined.id = a;
  database::MergeRecord record;
  record.target = a;
  record.source = "model 2";
  record.tsdf_rmse_m = 0.004;
  record.tsdf_overlap = 3415;
  record.scene_checks = 5;
  ASSERT_TRUE(store->absorbModel(model::cloneModel(joined), record, b).ok());
  auto check = [&] {
    EXPECT_EQ(diffModels(*store->model(a).value(), joined), "");
    EXPECT_EQ(store->model(b).status().code(), absl::StatusCode::kNotFound);
    EXPECT_EQ(store->modelIds().value(), std::vector<int64_t>{a});
    ModelQuery query;
    query.include_merged = true;
    const auto summaries = store->modelSummaries(query).value();
    ASSERT_EQ(summaries.size(), 2u);
    EXPECT_EQ(summaries[1].id, b);
    EXPECT_EQ(summaries[1].state, "merged");
    EXPECT_EQ(summaries[1].merged_into, a);
    EXPECT_TRUE(summaries[1].observations.empty());
    EXPECT_EQ(summaries[0].observations.size(), 2u);
    const auto records = store->mergeRecordsInto(a).value();
    ASSERT_EQ(records.size(), 1u);
    EXPECT_EQ(records[0].source, "model 2");
    EXPECT_EQ(records[0].tsdf_overlap, 3415u);
    EXPECT_EQ(store->stats().value().merged_models, 1);
  };
  check();
  // Again, or into itself: refused, and nothing changes.
  model::ObjectModel again = makeStoreModel(4, 1);
  again.id = a;
  const Status twice = store->absorbModel(model::cloneModel(again), record, b);
  EXPECT_EQ(twice.code(), absl::StatusCode::kNotFound) << twice;
  EXPECT_THAT(twice.message(), HasSubstr("merging object model 2 into object model 1"));
  EXPECT_EQ(store->absorbModel(std::move(again), record, a).code(),
            absl::StatusCode::kInvalidArgument);
  check();
  store.reset();
  store = openStore(dir / "db.sqlite");
  check();
}

TEST(SqliteStore, RawSegmentsRoundTripAndAReExtractionReplacesTheRow) {
  TempDir dir;
  auto store = openStore(dir / "db.sqlite");
  auto first = makeRawSegment("monday", 4, 1);
  first.parts = {4, 9, 12};  // a whole object of three GSM labels
  for (size_t i = 0; i < first.voxels.size(); ++i) first.voxel_parts.push_back(first.parts[i % 3]);
  ASSERT_TRUE(store->putRawSegment(first).ok());
  auto loaded = store->rawSegment({"monday", 4});
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  EXPECT_TRUE((*loaded)->T_world_segment.matrix() == first.T_world_segment.matrix());
  EXPECT_EQ(diffLayers(*(*loaded)->grid, *first.grid), "");
  EXPECT_EQ((*loaded)->voxels, first.voxels);
  EXPECT_EQ((*loaded)->extraction_frame, first.extraction_frame);
  EXPECT_EQ((*loaded)->parts, first.parts);
  EXPECT_EQ((*loaded)->voxel_parts, first.voxel_parts);
  // Voxel parts must match the voxels one to one.
  auto uneven = makeRawSegment("monday", 5, 1);
  uneven.voxel_parts = {5};
  ASSERT_GT(uneven.voxels.size(), 1u);
  const Status refused = store->putRawSegment(uneven);
  EXPECT_EQ(refused.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(std::string(refused.message()).find("1 voxel parts for"), std::string::npos)
      << refused.message();

  auto again = makeRawSegment("monday", 4, 2);
  again.parts = {4};
  ASSERT_TRUE(store->putRawSegment(again).ok());
  EXPECT_EQ(store->rawSegment({"monday", 4}).value()->voxels, again.voxels);
  EXPECT_EQ(store->rawSegment({"monday", 4}).value()->parts, again.parts);
  EXPECT_TRUE(store->rawSegment({"monday", 4}).value()->voxel_parts.empty()) << "none recorded";
  const StoreStats stats = store->stats().value();
  for (const auto& t : stats.tables) {
    if (t.table == "raw_segments") {
      EXPECT_EQ(t.rows, 1);  // still one row
    }
  }
  EXPECT_EQ(store->rawSegment({"monday", 5}).status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(store->rawSegment({"tuesday", 4}).status().code(), absl::StatusCode::kNotFound);
}

TEST(SqliteStore, ScenesRoundTripPerBlockAndSurviveReopen) {
  TempDir dir;
  const model::ObjectModel m = makeStoreModel(9, 1);
  auto scene = std::make_shared<const tsdf::TsdfLayer>(m.grid.clone());
  {
    auto store = openStore(dir / "db.sqlite");
    EXPECT_EQ(store->scene("monday").value(), nullptr);
    ASSERT_TRUE(store->putScene("monday", scene).ok());
    EXPECT_EQ(store->putScene("monday", nullptr).code(), absl::StatusCode::kInvalidArgument);
  }
  auto store = openStore(dir / "db.sqlite");
  const auto loaded = store->scene("monday");
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  ASSERT_NE(*loaded, nullptr);
  EXPECT_EQ(diffLayers(**loaded, *scene), "");
  EXPECT_EQ(store->sceneLabels("monday").value(), nullptr);  // stored without labels
  // With labels: every voxel's main label, per block.
  auto labels = std::make_shared<gsm::LabelBlocks>();
  for (const auto& [index, block] : scene->blocks()) {
    std::vector<gsm::Label> l(block->voxels().size());
    for (size_t i = 0; i < l.size(); ++i) l[i] = gsm::Label(i % 7 == 0 ? 0 : 40 + index.x() + i % 3);
    labels->emplace(index, std::move(l));
  }
  ASSERT_TRUE(store->putScene("labelled", scene, labels).ok());
  auto wrong = std::make_shared<gsm::LabelBlocks>(*labels);
  wrong->begin()->second.pop_back();
  EXPECT_EQ(store->putScene("labelled", scene, wrong).code(), absl::StatusCode::kInvalidArgument);
  store.reset();
  store = openStore(dir / "db.sqlite");
  const auto loaded_labels = store->sceneLabels("labelled");
  ASSERT_TRUE(loaded_labels.ok()) << loaded_labels.status();
  ASSERT_NE(*loaded_labels, nullptr);
  EXPECT_TRUE(**loaded_labels == *labels);
  // Replacing the scene replaces all its blocks.
  tsdf::TsdfLayer smaller = tsdf::TsdfLayer::create(0.02f, 8).value();
  smaller.allocateBlock({5, 5, 5}).voxels()[0].weight = 2.0f;
  ASSERT_TRUE(store->putScene("monday", std::make_shared<const tsdf::TsdfLayer>(smaller.clone())).ok());
  store.reset();
  store = openStore(dir / "db.sqlite");
  EXPECT_EQ(diffLayers(*store->scene("monday").value(), smaller), "");
}

// The server saves an open session's live map now and then (docs/server.md): it reads back
// whole, replaces the earlier save, is not the session's scene map, survives an interrupted end
// and is deleted when the session ends.
TEST(SqliteStore, SavedLiveMapsRoundTripStayApartFromScenesAndGoWhenTheSessionEnds) {
  TempDir dir;
  const model::ObjectModel m = makeStoreModel(11, 1);
  const tsdf::TsdfLayer& map = m.grid;
  gsm::LabelBlocks labels;
  for (const auto& [index, block] : map.blocks()) {
    std::vector<gsm::Label> l(block->voxels().size());
    for (size_t i = 0; i < l.size(); ++i) l[i] = gsm::Label(i % 5 == 0 ? 0 : 7 + i % 2);
    labels.emplace(index, std::move(l));
  }
  auto store = openStore(dir / "db.sqlite");
  SessionInfo info;
  info.name = "monday";
  ASSERT_TRUE(store->beginSession(info).ok());
  EXPECT_EQ(store->savedMap("monday").value().map, nullptr);
  EXPECT_EQ(store->savedMap("nobody").value().map, nullptr);

  ASSERT_TRUE(store->putSavedMap("monday", 42, map, labels).ok());
  store.reset();
  store = openStore(dir / "db.sqlite");
  {
    const auto saved = store->savedMap("monday");
    ASSERT_TRUE(saved.ok()) << saved.status();
    EXPECT_EQ(saved->frames, 42);
    ASSERT_NE(saved->map, nullptr);
    EXPECT_EQ(diffLayers(*saved->map, map), "");
    ASSERT_NE(saved->labels, nullptr);
    EXPECT_TRUE(*saved->labels == labels);
  }
  EXPECT_EQ(store->scene("monday").value(), nullptr) << "a saved live map is not a scene map";
  EXPECT_EQ(store->sceneLabels("monday").value(), nullptr);
  const auto report = store->check();
  ASSERT_TRUE(report.ok()) << report.status();
  EXPECT_TRUE(report->ok());
  EXPECT_GE(report->blobs_checked, 2 * map.numBlocks());

  // A later save replaces every block of the earlier one.
  tsdf::TsdfLayer smaller = tsdf::TsdfLayer::create(map.voxelSize(), map.voxelsPerSide()).value();
  smaller.allocateBlock({5, 5, 5}).voxels()[0].weight = 2.0f;
  gsm::LabelBlocks smaller_labels;
  smaller_labels[{5, 5, 5}] = std::vector<gsm::Label>(smaller.block({5, 5, 5})->voxels().size(), 3);
  ASSERT_TRUE(store->putSavedMap("monday", 50, smaller, smaller_labels).ok());
  gsm::LabelBlocks wrong = smaller_labels;
  wrong.begin()->second.pop_back();
  EXPECT_EQ(store->putSavedMap("monday", 51, smaller, wrong).code(),
            absl::StatusCode::kInvalidArgument);
  {
    const auto saved = store->savedMap("monday").value();
    EXPECT_EQ(saved.frames, 50);
    EXPECT_EQ(diffLayers(*saved.map, smaller), "");
    EXPECT_TRUE(*saved.labels == smaller_labels);
  }
  // Interrupted: kept, the session may still be ended from it. Ended: gone, with its rows.
  ASSERT_TRUE(store->finishSession("monday", SessionState::kInterrupted, 50).ok());
  EXPECT_NE(store->savedMap("monday").value().map, nullptr);
  ASSERT_TRUE(store->finishSession("monday", SessionState::kEnded, 50).ok());
  EXPECT_EQ(store->savedMap("monday").value().map, nullptr);
  const StoreStats stats = store->stats().value();
  for (const auto& t : stats.tables) {
    if (t.table == "saved_blocks" || t.table == "saved_label_blocks") {
      EXPECT_EQ(t.rows, 0) << t.table;
    }
  }
}

// The decoded-scene cache keeps the most recently used maps only: a long-lived server with many
// sessions does not keep every map in memory. Evicted maps are decoded again, unchanged.
TEST(SqliteStore, TheSceneCacheIsBoundedAndEvictedScenesReadBackUnchanged) {
  TempDir dir;
  SqliteStoreOptions options;
  options.max_cached_scenes = 2;
  auto opened = SqliteStore::open((dir / "db.sqlite").string(), options);
  ASSERT_TRUE(opened.ok()) << opened.status();
  auto& store = *opened;
  std::vector<std::shared_ptr<const tsdf::TsdfLayer>> scenes;
  for (int s = 0; s < 4; ++s) {
    tsdf::TsdfLayer layer = tsdf::TsdfLayer::create(0.02f, 8).value();
    layer.allocateBlock({s, 0, 0}).voxels()[size_t(s)].weight = 1.0f + float(s);
    scenes.push_back(std::make_shared<const tsdf::TsdfLayer>(std::move(layer)));
    ASSERT_TRUE(store->putScene("s" + std::to_string(s), scenes.back()).ok());
  }
  // Reads in an order that evicts and reloads each of them at least once.
  for (int s : {0, 3, 1, 0, 2, 3, 1}) {
    const auto loaded = store->scene("s" + std::to_string(s));
    ASSERT_TRUE(loaded.ok()) << loaded.status();
    ASSERT_NE(*loaded, nullptr) << s;
    EXPECT_EQ(diffLayers(**loaded, *scenes[size_t(s)]), "") << s;
  }
  // The two most recent are served from memory: the very same object.
  EXPECT_EQ(store->scene("s1").value().get(), store->scene("s1").value().get());
  EXPECT_NE(store->scene("s0").value().get(), scenes[0].get()) << "s0 was evicted and decoded";
  options.max_cached_scenes = 0;
  EXPECT_FALSE(options.validate().ok());
}

TEST(SqliteStore, SessionsHaveALifecycle) {
  TempDir dir;
  auto store = openStore(dir / "db.sqlite");
  SessionInfo info;
  info.name = "monday";
  info.intrinsics_json = R"({"fx":525})";
  ASSERT_TRUE(store->beginSession(info).ok());
  EXPECT_EQ(store->beginSession(info).status().code(), absl::StatusCode::kAlreadyExists);
  ASSERT_TRUE(store->putRawSegment(makeRawSegment("tuesday", 1, 1)).ok());  // implicit session
  ASSERT_TRUE(store->finishSession("monday", SessionState::kEnded, 300).ok());
  EXPECT_EQ(store->finishSession("friday", SessionState::kEnded, 1).code(),
            absl::StatusCode::kNotFound);
  const auto sessions = store->sessions().value();
  ASSERT_EQ(sessions.size(), 2u);
  EXPECT_EQ(sessions[0].name, "monday");
  EXPECT_EQ(sessions[0].state, SessionState::kEnded);
  EXPECT_EQ(sessions[0].frames, 300);
  EXPECT_EQ(sessions[0].intrinsics_json, R"({"fx":525})");
  EXPECT_FALSE(sessions[0].ended_at.empty());
  EXPECT_EQ(sessions[1].name, "tuesday");
  EXPECT_EQ(sessions[1].state, SessionState::kOpen);
}

TEST(SqliteStore, AFlippedBlobByteFailsThatRowOnly) {
  TempDir dir;
  const auto path = dir / "db.sqlite";
  std::vector<model::ObjectModel> originals;
  {
    auto store = openStore(path);
    for (uint32_t seed = 1; seed <= 4; ++seed) {
      model::ObjectModel m = makeStoreModel(seed, 2);
      m.id = store->addModel(model::cloneModel(m)).value();
      originals.push_back(std::move(m));
    }
    ASSERT_TRUE(store->putScene("s0", std::make_shared<const tsdf::TsdfLayer>(originals[0].grid.clone())).ok());
  }
  flipBlobByte(path, "models", "descriptors", 2);
  flipBlobByte(path, "models", "grid", 3);
  auto store = openStore(path);
  const auto two = store->model(2);
  ASSERT_FALSE(two.ok());
  EXPECT_EQ(two.status().code(), absl::StatusCode::kDataLoss);
  EXPECT_THAT(two.status().message(), HasSubstr("models row 2, column descriptors"));
  EXPECT_THAT(two.status().message(), HasSubstr("checksum mismatch (expected"));
  EXPECT_THAT(store->model(3).status().message(), HasSubstr("models row 3, column grid"));
  EXPECT_EQ(diffModels(*store->model(1).value(), originals[0]), "");
  EXPECT_EQ(diffModels(*store->model(4).value(), originals[3]), "");
  EXPECT_EQ(store->modelIds().value().size(), 4u);
  // The prefilter's index leaves out the one whose descriptors are damaged and says why.
  const auto entries = store->matchEntries().value();
  EXPECT_EQ(entries.entries.size(), 3u);
  ASSERT_EQ(entries.skipped.size(), 1u);
  EXPECT_THAT(entries.skipped[0].message(), HasSubstr("models row 2"));
  const auto report = store->check().value();
  EXPECT_TRUE(report.sqlite_findings.empty());
  ASSERT_EQ(report.damaged.size(), 2u);
  EXPECT_EQ(report.damaged[0].table, "models");
  EXPECT_EQ(report.damaged[0].row, 3);
  EXPECT_EQ(report.damaged[0].column, "grid");
  EXPECT_EQ(report.damaged[1].row, 2);
  EXPECT_EQ(report.damaged[1].column, "descriptors");
  EXPECT_GT(report.blobs_checked, 20u);

  // A damaged scene block is named by session and block.
  store.reset();
  flipBlobByte(path, "scene_blocks", "tsdf", 1);
  store = openStore(path);
  const auto scene = store->scene("s0");
  ASSERT_FALSE(scene.ok());
  EXPECT_THAT(scene.status().message(), HasSubstr("scene of session s0, block"));
  EXPECT_EQ(store->check().value().damaged.size(), 3u);
}

TEST(SqliteStore, WrongFilesAreRefusedUntouched) {
  TempDir dir;
  {
    auto store = openStore(dir / "good.sqlite");
    for (uint32_t seed = 1; seed <= 20; ++seed) ASSERT_TRUE(store->addModel(makeStoreModel(seed, 3)).ok());
  }
  // Text file.
  ASSERT_TRUE(objdb::testing::writeTextFile(dir / "notes.txt", std::string(5000, 'x') + "\n"));
  auto text = SqliteStore::open((dir / "notes.txt").string());
  ASSERT_FALSE(text.ok());
  EXPECT_EQ(text.status().code(), absl::StatusCode::kDataLoss);
  EXPECT_THAT(text.status().message(), HasSubstr("not a database"));
  EXPECT_EQ(readFile(dir / "notes.txt"), std::string(5000, 'x') + "\n");

  // Another application's SQLite database.
  rawSql(dir / "other.sqlite", "CREATE TABLE t(x); INSERT INTO t VALUES (1);");
  const std::string other_before = readFile(dir / "other.sqlite");
  auto other = SqliteStore::open((dir / "other.sqlite").string());
  ASSERT_FALSE(other.ok());
  EXPECT_EQ(other.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_THAT(other.status().message(), HasSubstr("another application"));
  EXPECT_EQ(readFile(dir / "other.sqlite"), other_before);

  // A newer schema.
  std::filesystem::copy_file(dir / "good.sqlite", dir / "future.sqlite");
  rawSql(dir / "future.sqlite", "PRAGMA user_version = 99;");
  const std::string future_before = readFile(dir / "future.sqlite");
  auto future = SqliteStore::open((dir / "future.sqlite").string());
  ASSERT_FALSE(future.ok());
  EXPECT_EQ(future.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_THAT(future.status().message(), HasSubstr("schema version 99, newer than this build"));
  EXPECT_EQ(readFile(dir / "future.sqlite"), future_before);

  // Truncated to half.
  std::filesystem::copy_file(dir / "good.sqlite", dir / "half.sqlite");
  std::filesystem::resize_file(dir / "half.sqlite", std::filesystem::file_size(dir / "half.sqlite") / 2);
  const std::string half_before = readFile(dir / "half.sqlite");
  auto half = SqliteStore::open((dir / "half.sqlite").string());
  ASSERT_FALSE(half.ok());
  EXPECT_EQ(half.status().code(), absl::StatusCode::kDataLoss);
  EXPECT_THAT(half.status().message(), HasSubstr("half.sqlite"));
  EXPECT_EQ(readFile(dir / "half.sqlite"), half_before);

  // Missing file with create_if_missing off; a directory.
  SqliteStoreOptions no_create;
  no_create.create_if_missing = false;
  EXPECT_EQ(SqliteStore::open((dir / "none.sqlite").string(), no_create).status().code(),
            absl::StatusCode::kNotFound);
  EXPECT_EQ(SqliteStore::open(dir.path().string()).status().code(),
            absl::StatusCode::kFailedPrecondition);
  SqliteStoreOptions bad;
  bad.synchronous = "OFF";
  EXPECT_THAT(SqliteStore::open((dir / "x.sqlite").string(), bad).status().message(),
              HasSubstr("synchronous must be FULL or NORMAL"));
}

TEST(SqliteStore, ReadOnlyStoresReadAndRefuseWrites) {
  TempDir dir;
  { ASSERT_TRUE(openStore(dir / "db.sqlite")->addModel(makeStoreModel(1, 1)).ok()); }
  SqliteStoreOptions options;
  options.read_only = true;
  auto store = openStore(dir / "db.sqlite", options);
  ASSERT_NE(store, nullptr);
  EXPECT_TRUE(store->model(1).ok());
  EXPECT_EQ(store->addModel(makeStoreModel(2, 1)).status().code(),
            absl::StatusCode::kFailedPrecondition);
}

// What a file of an older schema holds must survive its migration: a session and its scene map
// (tables whose layout every schema since the first keeps; this build's model and raw-segment
// writes need the current schema's columns).
void addSessionWithScene(SqliteStore* store, const std::string& name) {
  SessionInfo info;
  info.name = name;
  ASSERT_TRUE(store->beginSession(info).ok());
  ASSERT_TRUE(store->putScene(name, std::make_shared<const tsdf::TsdfLayer>(
                                        makeStoreModel(1, 2).grid.clone())).ok());
}

void expectSessionWithScene(const SqliteStore& store, const std::string& name) {
  const auto sessions = store.sessions();
  ASSERT_TRUE(sessions.ok()) << sessions.status();
  ASSERT_EQ(sessions->size(), 1u);
  EXPECT_EQ(sessions->front().name, name);
  const auto scene = store.scene(name);
  ASSERT_TRUE(scene.ok() && *scene != nullptr);
  EXPECT_EQ((*scene)->numBlocks(), makeStoreModel(1, 2).grid.numBlocks());
}

TEST(SqliteStore, OlderSchemasAreMigratedAndAFailedMigrationChangesNothing) {
  TempDir dir;
  const auto path = (dir / "db.sqlite").string();
  std::vector<Migration> v1 = {schemaMigrations().front()};
  {
    auto store = SqliteStore::open(path, {}, v1);
    ASSERT_TRUE(store.ok()) << store.status();
    addSessionWithScene(store->get(), "monday");
  }
  // A step that fails half way rolls back: the file stays at version 1 with its data.
  std::vector<Migration> broken = v1;
  broken.push_back({2, "broken", "ALTER TABLE sessions ADD COLUMN note TEXT; SELECT * FROM nowhere;"});
  auto failed = SqliteStore::open(path, {}, broken);
  ASSERT_FALSE(failed.ok());
  EXPECT_THAT(failed.status().message(), HasSubstr("migrating to schema 2"));
  {
    auto store = SqliteStore::open(path, {}, v1);
    ASSERT_TRUE(store.ok()) << store.status();
    EXPECT_EQ((*store)->schema().version_after, 1);
    expectSessionWithScene(**store, "monday");
  }
  std::vector<Migration> v2 = v1;
  v2.push_back({2, "session notes", "ALTER TABLE sessions ADD COLUMN note TEXT NOT NULL DEFAULT '';"});
  auto migrated = SqliteStore::open(path, {}, v2);
  ASSERT_TRUE(migrated.ok()) << migrated.status();
  EXPECT_EQ((*migrated)->schema().version_before, 1);
  EXPECT_EQ((*migrated)->schema().version_after, 2);
  expectSessionWithScene(**migrated, "monday");
}

// One writer per file (the server and `objdb ingest` keep in-memory copies of what the file
// holds): a second writable open is refused while the first is open, readers are not, and the
// lock goes with the store.
TEST(SqliteStore, ASecondWriterOnTheSameFileIsRefusedUntilTheFirstCloses) {
  TempDir dir;
  const std::string path = (dir / "db.sqlite").string();
  auto first = SqliteStore::open(path);
  ASSERT_TRUE(first.ok()) << first.status();
  ASSERT_TRUE((*first)->addModel(makeStoreModel(1, 1)).ok());
  const auto second = SqliteStore::open(path);
  ASSERT_FALSE(second.ok());
  EXPECT_EQ(second.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_THAT(second.status().message(), HasSubstr("open for writing by another objdb store"));
  SqliteStoreOptions read_only;
  read_only.read_only = true;
  const auto reader = SqliteStore::open(path, read_only);
  ASSERT_TRUE(reader.ok()) << reader.status();
  EXPECT_EQ((*reader)->modelIds().value().size(), 1u);
  first->reset();
  const auto after = SqliteStore::open(path);
  ASSERT_TRUE(after.ok()) << after.status();
  EXPECT_TRUE((*after)->addModel(makeStoreModel(2, 1)).ok());
}

// This build's own migrations: a file of schema 1 (before saved live maps and room structure)
// opens as the current schema with its sessions and scenes, and takes models (structure
// flag and observation depth round-trip), raw segments and saved maps.
TEST(SqliteStore, AFileOfTheFirstSchemaIsMigratedToTheCurrentOne) {
  TempDir dir;
  const auto path = (dir / "db.sqlite").string();
  {
    auto store = SqliteStore::open(path, {}, {schemaMigrations().front()});
    ASSERT_TRUE(store.ok()) << store.status();
    addSessionWithScene(store->get(), "s");
  }
  auto store = SqliteStore::open(path);
  ASSERT_TRUE(store.ok()) << store.status();
  EXPECT_EQ((*store)->schema().version_before, 1);
  EXPECT_EQ((*store)->schema().version_after, currentSchemaVersion());
  expectSessionWithScene(**store, "s");
  model::ObjectModel structure = makeStoreModel(1, 2);
  structure.structure = true;
  const auto id = (*store)->addModel(makeStoreModel(1, 2));
  const auto wall = (*store)->addModel(std::move(structure));
  ASSERT_TRUE(id.ok() && wall.ok());
  EXPECT_FALSE((*store)->model(*id).value()->structure);
  EXPECT_TRUE((*store)->model(*wall).value()->structure);
  database::RawSegmentRecord segment;
  segment.key = {"s", 4};
  segment.grid = std::make_shared<const tsdf::TsdfLayer>(makeStoreModel(1, 2).grid.clone());
  segment.voxels = {tsdf::VoxelIndex(1, 2, 3)};
  segment.observation_depth_m = 2.75f;
  segment.parts = {4, 7};
  segment.voxel_parts = {7};
  ASSERT_TRUE((*store)->putRawSegment(segment).ok());
  EXPECT_EQ((*store)->rawSegment({"s", 4}).value()->voxel_parts, (std::vector<uint32_t>{7}));
  EXPECT_FLOAT_EQ((*store)->rawSegment({"s", 4}).value()->observation_depth_m, 2.75f);
  EXPECT_EQ((*store)->rawSegment({"s", 4}).value()->parts, (std::vector<uint32_t>{4, 7}));
  const model::ObjectModel source = makeStoreModel(1, 2);
  ASSERT_TRUE((*store)->putSavedMap("s", 3, source.grid, {}).ok());
  EXPECT_EQ((*store)->savedMap("s").value().frames, 3);
  EXPECT_TRUE((*store)->check().value().ok());
}

}  // namespace
}  // namespace objdb::storage
