// Readers list and load models while one writer inserts and merges: no reader ever sees a
// half-written model (its model row and its observation rows come from one snapshot), whether it
// reads through the writer's store object (pooled reader connections) or its own read-only store.
#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "storage/sqlite/sqlite_store.h"
#include "tests/storage/store_fixtures.h"
#include "tests/support/temp_dir.h"

namespace objdb::storage {
namespace {

using objdb::testing::makeStoreModel;
using objdb::testing::wholeModel;

TEST(SqliteStoreConcurrency, ReadersNeverSeeHalfWrittenModels) {
  objdb::testing::TempDir dir;
  const std::string path = (dir / "db.sqlite").string();
  SqliteStoreOptions options;
  options.synchronous = "NORMAL";  // the property under test is isolation, not durability
  auto writer_store = SqliteStore::open(path, options).value();
  ASSERT_TRUE(writer_store->addModel(makeStoreModel(1, 1)).ok());

  std::atomic<bool> done{false};
  std::atomic<size_t> loads{0}, broken{0}, errors{0};
  auto readLoop = [&](const SqliteStore& store) {
    while (!done.load()) {
      const auto ids = store.modelIds();
      if (!ids.ok()) {
        ++errors;
        continue;
      }
      for (int64_t id : *ids) {
        const auto m = store.model(id);
        if (!m.ok()) {
          ++errors;
          continue;
        }
        ++loads;
        if (!wholeModel(**m)) ++broken;
      }
    }
  };
  SqliteStoreOptions read_only;
  read_only.read_only = true;
  auto own_store = SqliteStore::open(path, read_only).value();
  std::vector<std::thread> readers;
  readers.emplace_back(readLoop, std::cref(*writer_store));
  readers.emplace_back(readLoop, std::cref(*writer_store));
  readers.emplace_back(readLoop, std::cref(*own_store));

  for (uint32_t i = 0; i < 60; ++i) {
    if (i % 2 == 0) {
      ASSERT_TRUE(writer_store->addModel(makeStoreModel(100 + i, 1 + int(i % 3))).ok());
    } else {
      // Merges grow a model: more observations, a larger cloud, more keypoints, in one unit.
      const auto ids = writer_store->modelIds().value();
      const int64_t target = ids[i % ids.size()];
      const size_t before = writer_store->model(target).value()->observations.size();
      model::ObjectModel grown = makeStoreModel(200 + i, int(before % 6) + 1);
      grown.id = target;
      ASSERT_TRUE(writer_store->replaceModel(std::move(grown), std::nullopt).ok());
    }
  }
  done = true;
  for (auto& t : readers) t.join();
  EXPECT_EQ(broken.load(), 0u);
  EXPECT_EQ(errors.load(), 0u);
  EXPECT_GT(loads.load(), 60u);
  EXPECT_EQ(writer_store->modelIds().value().size(), 31u);
}

// An online backup taken while a writer inserts and merges: each copy opens,
// passes every check, and holds only whole models — as many as were committed at some moment
// of the run. The writer never waits for the backups. A backup never overwrites a file.
TEST(SqliteStoreConcurrency, OnlineBackupsAreConsistentCopiesWhileAWriterCarriesOn) {
  objdb::testing::TempDir dir;
  const std::string path = (dir / "db.sqlite").string();
  auto store = SqliteStore::open(path).value();
  for (uint32_t i = 0; i < 5; ++i) ASSERT_TRUE(store->addModel(makeStoreModel(1 + i, 2)).ok());

  std::atomic<bool> done{false};
  std::atomic<int> written{5};
  std::thread writer([&] {
    for (uint32_t i = 0; i < 80 && !done.load(); ++i) {
      if (i % 2 == 0) {
        ASSERT_TRUE(store->addModel(makeStoreModel(100 + i, 1 + int(i % 3))).ok());
        ++written;
      } else {
        const auto ids = store->modelIds().value();
        model::ObjectModel grown = makeStoreModel(200 + i, int(i % 6) + 1);
        grown.id = ids[i % ids.size()];
        ASSERT_TRUE(store->replaceModel(std::move(grown), std::nullopt).ok());
      }
    }
  });
  std::vector<std::string> copies;
  for (int k = 0; k < 4; ++k) {
    copies.push_back((dir / ("copy" + std::to_string(k) + ".sqlite")).string());
    const auto report = store->backupTo(copies.back());
    ASSERT_TRUE(report.ok()) << report.status();
    EXPECT_GT(report->pages, 0);
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  done = true;
  writer.join();
  SqliteStoreOptions read_only;
  read_only.read_only = true;
  read_only.create_if_missing = false;
  for (const std::string& copy : copies) {
    SCOPED_TRACE(copy);
    auto backup = SqliteStore::open(copy, read_only);
    ASSERT_TRUE(backup.ok()) << backup.status();
    const auto report = (*backup)->check();
    ASSERT_TRUE(report.ok()) << report.status();
    EXPECT_TRUE(report->ok());
    const auto ids = (*backup)->modelIds().value();
    EXPECT_GE(ids.size(), 5u);
    EXPECT_LE(int(ids.size()), written.load());
    for (int64_t id : ids) EXPECT_TRUE(wholeModel(*(*backup)->model(id).value())) << id;
  }
  // A backup does not overwrite: the first copy stays as it was.
  const auto size = std::filesystem::file_size(copies.front());
  const auto again = store->backupTo(copies.front());
  EXPECT_EQ(again.status().code(), absl::StatusCode::kAlreadyExists) << again.status();
  EXPECT_EQ(std::filesystem::file_size(copies.front()), size);
  // A stale WAL of that name would be replayed over a new copy: refused too.
  const std::string stale = (dir / "stale.sqlite").string();
  std::ofstream(stale + "-wal") << "old";
  EXPECT_EQ(store->backupTo(stale).status().code(), absl::StatusCode::kAlreadyExists);
  EXPECT_FALSE(std::filesystem::exists(stale));
  // Nowhere to write: an error.
  EXPECT_FALSE(store->backupTo((dir / "missing" / "copy.sqlite").string()).ok());
  // No temporary file is left behind by any of these.
  for (const auto& entry : std::filesystem::directory_iterator(dir.path())) {
    EXPECT_EQ(entry.path().string().find(".partial"), std::string::npos) << entry.path();
  }
}

}  // namespace
}  // namespace objdb::storage
