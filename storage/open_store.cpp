#include "storage/open_store.h"

#include <utility>

namespace objdb::storage {

StatusOr<std::unique_ptr<Store>> openStore(const std::string& target,
                                           const StoreOptions& options) {
  if (isPostgresTarget(target)) {
    OBJDB_ASSIGN_OR_RETURN(std::unique_ptr<PostgresStore> store,
                           PostgresStore::open(target, options.postgres));
    return std::unique_ptr<Store>(std::move(store));
  }
  OBJDB_ASSIGN_OR_RETURN(std::unique_ptr<SqliteStore> store,
                         SqliteStore::open(target, options.sqlite));
  return std::unique_ptr<Store>(std::move(store));
}

}  // namespace objdb::storage
