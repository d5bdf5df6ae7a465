// Private to storage/postgres/: what the files of PostgresStore's implementation share (its
// connection pool and scene cache, the session row of a write, the saved map's deletion). Not
// included outside storage/postgres/.
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

// Row `row` of `result`, for the row readers of storage/row_codec.h.
class ResultRow final : public Row {
 public:
  ResultRow(const pg::Result& result, int row) : result_(result), row_(row) {}
  bool isNull(int c) const override { return result_.isNull(row_, c); }
  int64_t integer(int c) const override { return result_.integer(row_, c); }
  double real(int c) const override { return result_.real(row_, c); }
  std::string text(int c) const override { return result_.text(row_, c); }
  std::string_view bytes(int c) const override { return result_.bytes(row_, c); }

 private:
  const pg::Result& result_;
  const int row_;
};

// The id of session `name`, created (state open) when it has no row yet; inside the caller's
// write transaction. INVALID_ARGUMENT for an empty name.
StatusOr<int64_t> sessionIdForWrite(const pg::Connection& c, const std::string& name);

// Deletes the saved map of `session` (inside the caller's write transaction).
Status deleteSavedMap(const pg::Connection& c, const std::string& session);

}  // namespace pgstore
}  // namespace objdb::storage
