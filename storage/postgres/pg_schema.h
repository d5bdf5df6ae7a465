// The PostgreSQL store's schema and its forward migrations. The database carries a table
// objdb_meta with the application ('objdb') and the schema version. Opening checks both before
// writing anything: a database with tables of another application or a newer schema is refused,
// untouched; an older schema is migrated one step per transaction, under an advisory lock, so
// that servers starting at once migrate it once (the version moves with the DDL: a crash leaves
// either the old or the new schema).
#pragma once

#include <string>
#include <vector>

#include "core/common/status.h"
#include "storage/postgres/pg_util.h"
#include "storage/shared_schema.h"

namespace objdb::storage::pg {

const std::vector<Migration>& schemaMigrations();

// Brings the database of `connection` to the last of `migrations`. Errors: FAILED_PRECONDITION
// for a database of another application or a newer schema (nothing written), or the migration's
// own error (rolled back).
StatusOr<SchemaState> prepareSchema(const Connection& connection, const std::string& describe,
                                    const std::vector<Migration>& migrations);

// SQL for "now" as the rows keep times: ISO-8601 UTC with milliseconds (as the SQLite store).
inline constexpr const char* kNow =
    "to_char(clock_timestamp() AT TIME ZONE 'UTC', 'YYYY-MM-DD\"T\"HH24:MI:SS.MS\"Z\"')";

}  // namespace objdb::storage::pg
