// Opens the server's store (storage/store.h) for a target: today a SQLite file path
// (storage/sqlite/sqlite_store.h), with its options.
#pragma once

#include <memory>
#include <string>

#include "core/common/status.h"
#include "storage/sqlite/sqlite_store.h"
#include "storage/store.h"

namespace objdb::storage {

// The store of the SQLite file at `target` (SqliteStore::open's errors: DATA_LOSS for a corrupt
// file, FAILED_PRECONDITION for a foreign or newer one or one another writer holds, ...).
StatusOr<std::unique_ptr<Store>> openStore(const std::string& target,
                                           const SqliteStoreOptions& options);

}  // namespace objdb::storage
