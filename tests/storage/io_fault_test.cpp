// I/O errors and a full disk under the store: a fault-injecting VFS fails the
// k-th write, sync or truncate of one insert, once and from then on, for every k. Each time the
// insert reports UNAVAILABLE naming what it was doing, nothing crashes, and once the fault is
// lifted the file passes its checks, the model is wholly there or wholly absent, and the same
// store takes the next insert without a restart.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <functional>

#include "absl/strings/str_format.h"
#include "storage/sqlite/sqlite_store.h"
#include "tests/storage/store_fixtures.h"
#include "tests/support/faulty_vfs.h"
#include "tests/support/temp_dir.h"

namespace objdb::storage {
namespace {

using objdb::testing::diffModels;
using objdb::testing::FaultyVfs;
using objdb::testing::makeStoreModel;
using objdb::testing::TempDir;
using ::testing::HasSubstr;

std::unique_ptr<SqliteStore> openStore(const std::string& path) {
  auto store = SqliteStore::open(path);
  EXPECT_TRUE(store.ok()) << store.status();
  return store.ok() ? *std::move(store) : nullptr;
}

// The file passes PRAGMA integrity_check and every blob check; `present` is readable and whole,
// `absent` is not there.
using Present = std::vector<std::pair<int64_t, const model::ObjectModel*>>;

StatusOr<int64_t> add(SqliteStore* store, const model::ObjectModel& m) {
  return store->addModel(model::cloneModel(m));
}

void expectConsistent(const SqliteStore& store, const Present& present, size_t expected_models) {
  const auto report = store.check();
  ASSERT_TRUE(report.ok()) << report.status();
  EXPECT_TRUE(report->ok()) << (report->engine_findings.empty() ? "blob damage"
                                                                  : report->engine_findings[0]);
  const auto ids = store.modelIds();
  ASSERT_TRUE(ids.ok()) << ids.status();
  EXPECT_EQ(ids->size(), expected_models);
  for (const auto& [id, expected] : present) {
    const auto stored = store.model(id);
    ASSERT_TRUE(stored.ok()) << "model " << id << ": " << stored.status();
    model::ObjectModel want = model::cloneModel(*expected);
    want.id = id;
    EXPECT_EQ(diffModels(**stored, want), "") << "model " << id;
  }
}

// One write under test on a store that holds `first` as model `first_id`: it returns the id of
// the model it wrote (a new one, or first_id when it replaces it) and whether it recorded a merge.
using Write = std::function<StatusOr<int64_t>(SqliteStore* store, int64_t first_id)>;

// Fails each write, sync and truncate of `write`, once and then persistently, and checks what the
// store says and holds afterwards. With `absorbed`, the store also holds it (as model first_id +
// 1) before the write, and a write that succeeds has taken it out of the active models.
void sweepFaults(FaultyVfs* vfs, const Write& write, const model::ObjectModel& written,
                 size_t merges_when_done, const model::ObjectModel* absorbed = nullptr) {
  const model::ObjectModel first = makeStoreModel(1, 2);
  const model::ObjectModel third = makeStoreModel(3, 1);

  // How many writes, syncs and truncates the write makes.
  int64_t operations = 0;
  {
    TempDir dir;
    auto store = openStore((dir / "db.sqlite").string());
    ASSERT_NE(store, nullptr);
    const auto first_id = add(store.get(), first);
    ASSERT_TRUE(first_id.ok()) << first_id.status();
    if (absorbed != nullptr) ASSERT_EQ(add(store.get(), *absorbed).value(), *first_id + 1);
    vfs->failAt(0, false);
    const auto done = write(store.get(), *first_id);
    ASSERT_TRUE(done.ok()) << done.status();
    operations = vfs->operations();
    vfs->lift();
  }
  ASSERT_GE(operations, 3) << "a write transaction appends to the WAL and syncs it";

  int failed = 0, committed_anyway = 0;
  for (const bool persistent : {false, true}) {
    for (int64_t k = 1; k <= operations; ++k) {
      SCOPED_TRACE(::testing::Message() << "operation " << k << " of " << operations
                                        << (persistent ? ", persistent" : ", once"));
      TempDir dir;
      const std::string path = (dir / "db.sqlite").string();
      auto store = openStore(path);
      ASSERT_NE(store, nullptr);
      const auto first_id = add(store.get(), first);
      ASSERT_TRUE(first_id.ok()) << first_id.status();
      if (absorbed != nullptr) ASSERT_EQ(add(store.get(), *absorbed).value(), *first_id + 1);

      vfs->failAt(k, persistent);
      const StatusOr<int64_t> done = write(store.get(), *first_id);
      EXPECT_GE(vfs->failures(), 1) << "the fault was not reached";
      vfs->lift();

      Present present;
      size_t merges = 0;
      if (done.ok()) {
        ++committed_anyway;  // the fault hit after the commit point
        present.push_back({*done, &written});
        if (*done != *first_id) present.push_back({*first_id, &first});
        merges = merges_when_done;
      } else {
        ++failed;
        EXPECT_EQ(done.status().code(), absl::StatusCode::kUnavailable) << done.status();
        EXPECT_THAT(std::string(done.status().message()), HasSubstr("I/O error"));
        EXPECT_THAT(std::string(done.status().message()), HasSubstr("model"));
        present.push_back({*first_id, &first});
        if (absorbed != nullptr) present.push_back({*first_id + 1, absorbed});
      }
      expectConsistent(*store, present, present.size());
      EXPECT_EQ(store->mergeRecords().value().size(), merges);

      // The same store carries on, and the reopened file says the same.
      const auto third_id = add(store.get(), third);
      ASSERT_TRUE(third_id.ok()) << third_id.status();
      present.push_back({*third_id, &third});
      expectConsistent(*store, present, present.size());
      store.reset();
      store = openStore(path);
      ASSERT_NE(store, nullptr);
      expectConsistent(*store, present, present.size());
      EXPECT_EQ(store->mergeRecords().value().size(), merges);
    }
  }
  // Most faults must be reported: an I/O layer that swallowed them would pass every check above
  // with each write "ok".
  EXPECT_GT(failed, committed_anyway);
}

TEST(SqliteStoreIoFaults, EveryFailedWriteSyncOrTruncateOfAnInsertLeavesTheModelWhollyThereOrAbsent) {
  FaultyVfs vfs;
  const model::ObjectModel second = makeStoreModel(2, 3);
  sweepFaults(&vfs, [&](SqliteStore* store, int64_t) { return add(store, second); }, second, 0);
}

// `written` as model first_id, with the record of what merged into it.
std::pair<model::ObjectModel, database::MergeRecord> mergedInto(int64_t first_id,
                                                               const model::ObjectModel& written,
                                                               std::string source) {
  model::ObjectModel m = model::cloneModel(written);
  m.id = first_id;
  database::MergeRecord record;
  record.target = first_id;
  record.source = std::move(source);
  record.T_target_source = written.observations[1].T_object_segment;
  record.icp_rmse_m = 0.01;
  record.tsdf_rmse_m = 0.005;
  record.tsdf_overlap = 3000;
  return {std::move(m), record};
}

TEST(SqliteStoreIoFaults, EveryFailedWriteSyncOrTruncateOfAMergeLeavesTheOldModelOrTheMergedOne) {
  FaultyVfs vfs;
  const model::ObjectModel merged = makeStoreModel(4, 3);
  const Write merge = [&](SqliteStore* store, int64_t first_id) -> StatusOr<int64_t> {
    auto [m, record] = mergedInto(first_id, merged, "segment s1/7");
    OBJDB_RETURN_IF_ERROR(store->replaceModel(std::move(m), record));
    return first_id;
  };
  sweepFaults(&vfs, merge, merged, 1);
}

// One model merged into another (DatabaseParams::merge_co_accepted): both as they were, or the
// joined one alone with the other in state merged.
TEST(SqliteStoreIoFaults, EveryFailedWriteSyncOrTruncateOfAJoinLeavesBothModelsOrTheJoinedOne) {
  FaultyVfs vfs;
  const model::ObjectModel joined = makeStoreModel(4, 3);
  const model::ObjectModel other = makeStoreModel(5, 1);
  const Write join = [&](SqliteStore* store, int64_t first_id) -> StatusOr<int64_t> {
    auto [m, record] = mergedInto(first_id, joined, absl::StrFormat("model %d", first_id + 1));
    OBJDB_RETURN_IF_ERROR(store->absorbModel(std::move(m), record, first_id + 1));
    return first_id;
  };
  sweepFaults(&vfs, join, joined, 1, &other);
}

TEST(SqliteStoreIoFaults, AFullDiskIsResourceExhaustedAndTheStoreGoesOnOnceThereIsSpace) {
  FaultyVfs vfs;
  TempDir dir;
  const std::string path = (dir / "db.sqlite").string();
  auto store = openStore(path);
  ASSERT_NE(store, nullptr);
  const model::ObjectModel small = makeStoreModel(1, 1);
  const model::ObjectModel large = makeStoreModel(2, 400);
  const auto small_id = add(store.get(), small);
  ASSERT_TRUE(small_id.ok()) << small_id.status();

  // No file may grow beyond what the largest one holds now, plus one page.
  int64_t largest = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir.path())) {
    largest = std::max<int64_t>(largest, int64_t(entry.file_size()));
  }
  vfs.capFileBytes(largest + 4096);
  const StatusOr<int64_t> added = add(store.get(), large);
  EXPECT_GE(vfs.failures(), 1);
  vfs.lift();
  ASSERT_FALSE(added.ok());
  EXPECT_EQ(added.status().code(), absl::StatusCode::kResourceExhausted) << added.status();
  EXPECT_THAT(std::string(added.status().message()), HasSubstr("full"));
  expectConsistent(*store, {{*small_id, &small}}, 1);

  const auto retried = add(store.get(), large);
  ASSERT_TRUE(retried.ok()) << retried.status();
  expectConsistent(*store, {{*small_id, &small}, {*retried, &large}}, 2);
  store.reset();
  store = openStore(path);
  ASSERT_NE(store, nullptr);
  expectConsistent(*store, {{*small_id, &small}, {*retried, &large}}, 2);
}

}  // namespace
}  // namespace objdb::storage
