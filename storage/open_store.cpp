#include "storage/open_store.h"

#include <utility>

namespace objdb::storage {

StatusOr<std::unique_ptr<Store>> openStore(const std::string& target,
                                           const SqliteStoreOptions& options) {
  OBJDB_ASSIGN_OR_RETURN(std::unique_ptr<SqliteStore> store, SqliteStore::open(target, options));
  return std::unique_ptr<Store>(std::move(store));
}

}  // namespace objdb::storage
