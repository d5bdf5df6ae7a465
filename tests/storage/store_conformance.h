// The Store conformance suite (storage/store.h): the same tests run against every backend, one
// instantiation per backend (sqlite_conformance_test.cpp, postgres_conformance_test.cpp). The
// tests (store_conformance_test.cpp, store_conformance_maps_test.cpp) use only what the Store
// interface promises and open their stores through storage::openStore; what only one backend
// does (files, WAL, read-only opens, backups, migrations) is tested in that backend's own tests.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>

#include <gtest/gtest.h>

#include "core/common/status.h"
#include "storage/open_store.h"
#include "storage/store.h"

namespace objdb::testing {

struct StoreBackend {
  std::string name;  // "Sqlite", "Postgres" (gtest instantiation prefix)
  // The target (file path or libpq URI) of a new, empty store; a new one on every call.
  std::function<StatusOr<std::string>()> fresh_target;
};

// The name generator of the instantiations: just the backend's name.
inline std::string storeBackendName(const ::testing::TestParamInfo<StoreBackend>& info) {
  return info.param.name;
}

// Rows of `table` in `stats`; −1 when the table is not listed.
inline int64_t tableRows(const storage::StoreStats& stats, const std::string& table) {
  for (const auto& t : stats.tables) {
    if (t.table == table) return t.rows;
  }
  return -1;
}

class StoreConformance : public ::testing::TestWithParam<StoreBackend> {
 protected:
  // The target of a new, empty store of the backend under test. On failure the test has a fatal
  // failure and the result is empty (open() then returns null).
  std::string freshTarget() {
    StatusOr<std::string> target = GetParam().fresh_target();
    if (target.ok()) return *target;
    [&] { FAIL() << GetParam().name << ": no fresh store target: " << target.status(); }();
    return "";
  }

  // The store of `target` through storage::openStore; null, with the test failed by the status
  // message, when it cannot be opened (or an earlier helper already failed fatally). Reopening:
  // destroy the store object, open the target again.
  std::unique_ptr<storage::Store> open(const std::string& target,
                                       storage::StoreOptions options = {}) {
    if (HasFatalFailure()) return nullptr;
    StatusOr<std::unique_ptr<storage::Store>> store = storage::openStore(target, options);
    if (store.ok()) return std::move(*store);
    // Not the target itself: a URI may carry a password (the backends' messages redact it).
    [&] { FAIL() << "opening a " << GetParam().name << " store: " << store.status(); }();
    return nullptr;
  }
};

}  // namespace objdb::testing
