// Private to storage/postgres/: what the files of PostgresStore's implementation share (its
// connection pool and scene cache, the session row of a write, the map tables). Not included
// outside storage/postgres/.
#pragma once

#include <cstdint>
#include <functional>
#include <mutex>
#include <optional>
#include <string>

#include "core/common/status.h"
#include "storage/postgres/pg_schema.h"
#include "storage/postgres/pg_util.h"
#include "storage/postgres/postgres_store.h"
#include "storage/row_codec.h"

namespace objdb::storage {

class PostgresStore::Impl {
 public:
  Impl(const std::string& uri, const std::string& describe, const PostgresStoreOptions& options)
      : options(options),
        uri(uri),
        pool(uri, describe, options.pool_size, options.connect_timeout_s),
        scenes(size_t(options.max_cached_scenes)) {}

  // One write transaction (READ COMMITTED with row locks, retried on deadlock), annotated with `context`.
  Status write(std::string_view context, const std::function<Status(const pg::Connection&)>& body) {
    return pool.transact(pg::ConnectionPool::Kind::kWrite, options.max_transaction_retries, context,
                         body);
  }
  // One read snapshot.
  Status read(std::string_view context,
              const std::function<Status(const pg::Connection&)>& body) const {
    return pool.transact(pg::ConnectionPool::Kind::kRead, options.max_transaction_retries, context,
                         body);
  }

  const PostgresStoreOptions options;
  const std::string uri;
  pg::ConnectionPool pool;
  SceneCache scenes;
  // The writer lock (postgres_fleet.cpp): one holder in this process at a time, and a session
  // advisory lock on `writer` across processes.
  std::mutex writer_mutex;
  std::optional<pg::Connection> writer;
};

namespace pgstore {

// The id of session `name`, created (state open) when it has no row yet; inside the caller's
// write transaction. INVALID_ARGUMENT for an empty name.
StatusOr<int64_t> sessionIdForWrite(const pg::Connection& c, const std::string& name);

// The tables of one kind of stored map: a session's scene map, or its saved live map.
struct MapTables {
  const char* what;  // in messages: "scene" or "saved map"
  const char* maps;
  const char* blocks;
  const char* label_blocks;
  bool has_frames;
};
inline constexpr MapTables kSceneTables{"scene", "scene_maps", "scene_blocks",
                                        "scene_label_blocks", false};
inline constexpr MapTables kSavedTables{"saved map", "saved_maps", "saved_blocks",
                                        "saved_label_blocks", true};

// Deletes the saved map of `session` (inside the caller's write transaction).
Status deleteSavedMap(const pg::Connection& c, const std::string& session);

}  // namespace pgstore
}  // namespace objdb::storage
