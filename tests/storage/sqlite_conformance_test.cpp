// The Store conformance suite (store_conformance.h) against SqliteStore: every store a new file in
// a new temporary directory, removed when the test program exits.
#include <memory>
#include <mutex>
#include <vector>

#include <gtest/gtest.h>

#include "tests/storage/store_conformance.h"
#include "tests/support/temp_dir.h"

namespace objdb::testing {
namespace {

StatusOr<std::string> freshSqliteFile() {
  static std::mutex mutex;
  static std::vector<std::unique_ptr<TempDir>> dirs;  // kept until exit: stores outlive calls
  std::lock_guard lock(mutex);
  dirs.push_back(std::make_unique<TempDir>());
  return (*dirs.back() / "store.sqlite").string();
}

INSTANTIATE_TEST_SUITE_P(Sqlite, StoreConformance,
                         ::testing::Values(StoreBackend{"Sqlite", freshSqliteFile}),
                         storeBackendName);

}  // namespace
}  // namespace objdb::testing
