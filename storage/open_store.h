// Opens the server's store (storage/store.h) for a target: a PostgreSQL database when the target
// is a libpq URI (postgresql://… or postgres://…; storage/postgres/postgres_store.h), else the
// SQLite file at that path (storage/sqlite/sqlite_store.h).
#pragma once

#include <memory>
#include <string>

#include "core/common/status.h"
#include "storage/postgres/postgres_store.h"
#include "storage/sqlite/sqlite_store.h"
#include "storage/store.h"

namespace objdb::storage {

// Each backend's options; openStore uses the ones of the backend the target names.
struct StoreOptions {
  SqliteStoreOptions sqlite;
  PostgresStoreOptions postgres;
};

// The store of `target` (the backend's open() errors: for SQLite DATA_LOSS for a corrupt file,
// FAILED_PRECONDITION for a foreign or newer one or one another writer holds; for PostgreSQL
// UNAVAILABLE for an unreachable server, UNAUTHENTICATED for refused credentials, ...).
StatusOr<std::unique_ptr<Store>> openStore(const std::string& target,
                                           const StoreOptions& options = {});

}  // namespace objdb::storage
