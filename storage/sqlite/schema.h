// The store's schema and its forward migrations. A database file carries SQLite's
// `application_id` (objdb's id) and `user_version` (the schema version). Opening checks both
// before writing anything: a file that is not SQLite, another application's database or a
// newer schema is refused, untouched; an older schema is migrated in one transaction per step
// (the version moves with the DDL, so a crash leaves either the old or the new schema).
#pragma once

#include <string>
#include <vector>

#include "core/common/status.h"
#include "storage/shared_schema.h"
#include "storage/sqlite/sqlite_util.h"

namespace objdb::storage {

inline constexpr int32_t kApplicationId = 0x4F424A44;  // "OBJD"

// objdb's migrations, in order; the last one's version is the current schema.
const std::vector<Migration>& schemaMigrations();
int currentSchemaVersion();

// Checks the file's identity and version and brings it to the last of `migrations`. Errors:
// FAILED_PRECONDITION for a foreign or newer file (nothing written), DATA_LOSS when SQLite finds
// it corrupt or not a database, or the migration's own error (rolled back).
StatusOr<SchemaState> prepareSchema(const Connection& connection, const std::string& path,
                                    const std::vector<Migration>& migrations, bool read_only);

}  // namespace objdb::storage
