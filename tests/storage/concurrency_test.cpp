// Readers list and load models while one writer inserts and merges: no reader ever sees a
// half-written model (its model row and its observation rows come from one snapshot), whether it
// reads through the writer's store object (pooled reader connections) or its own read-only store.
#include <atomic>
#include <thread>

#include <gtest/gtest.h>

#include "storage/sqlite_store.h"
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

}  // namespace
}  // namespace objdb::storage
