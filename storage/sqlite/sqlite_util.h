// Thin RAII over the SQLite C API for the store: a connection, prepared statements with bound
// values, a write transaction (BEGIN IMMEDIATE) and a read snapshot (BEGIN DEFERRED), and the
// one mapping from SQLite result codes to Status codes (BUSY/IOERR →
// UNAVAILABLE, FULL → RESOURCE_EXHAUSTED, CORRUPT/NOTADB → DATA_LOSS).
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

#include <sqlite3.h>

#include "absl/strings/str_format.h"
#include "core/common/status.h"

namespace objdb::storage {

// A Status for SQLite result `rc` with the connection's message and what we were doing.
Status sqliteStatus(int rc, sqlite3* db, std::string_view context);

struct ConnectionOptions {
  bool read_only = false;
  bool create = false;       // create the file when missing (never with read_only)
  int busy_timeout_ms = 5000;
  std::string synchronous = "FULL";  // FULL or NORMAL (see docs/storage.md)
};

class Connection {
 public:
  static StatusOr<Connection> open(const std::string& path, const ConnectionOptions& options);
  Connection(Connection&& other) noexcept : db_(other.db_) { other.db_ = nullptr; }
  Connection& operator=(Connection&& other) noexcept;
  Connection(const Connection&) = delete;
  Connection& operator=(const Connection&) = delete;
  ~Connection();

  sqlite3* get() const { return db_; }
  // Runs SQL without results (several statements allowed).
  Status exec(std::string_view sql, std::string_view context) const;
  // The single integer result of a query (PRAGMA user_version, COUNT(*), ...).
  StatusOr<int64_t> queryInt(std::string_view sql, std::string_view context) const;

 private:
  explicit Connection(sqlite3* db) : db_(db) {}
  sqlite3* db_ = nullptr;
};

class Statement {
 public:
  static StatusOr<Statement> prepare(const Connection& connection, std::string_view sql);
  // The statement absl::StrFormat makes of `format` and `args` (names and SQL, never values:
  // those are bound).
  template <typename... Args>
  static StatusOr<Statement> prepare(const Connection& connection,
                                     const absl::FormatSpec<Args...>& format, const Args&... args) {
    return prepare(connection, absl::StrFormat(format, args...));
  }
  Statement(Statement&& other) noexcept : db_(other.db_), stmt_(other.stmt_) {
    other.stmt_ = nullptr;
  }
  Statement(const Statement&) = delete;
  Statement& operator=(const Statement&) = delete;
  Statement& operator=(Statement&&) = delete;
  ~Statement();

  // Parameters are 1-based, as in SQLite.
  Statement& bind(int i, int64_t value);
  Statement& bind(int i, double value);
  Statement& bind(int i, std::string_view text);  // TEXT
  Statement& bindBlob(int i, std::string_view bytes);
  Statement& bindNull(int i);

  // One step: true when a row is ready, false when done.
  StatusOr<bool> step();
  // Steps to the end (for statements without rows).
  Status run();
  Status reset();

  int64_t columnInt(int i) const { return sqlite3_column_int64(stmt_, i); }
  double columnDouble(int i) const { return sqlite3_column_double(stmt_, i); }
  bool columnIsNull(int i) const { return sqlite3_column_type(stmt_, i) == SQLITE_NULL; }
  std::string columnText(int i) const;
  // Valid until the next step/reset.
  std::string_view columnBlob(int i) const;

 private:
  Statement(sqlite3* db, sqlite3_stmt* stmt) : db_(db), stmt_(stmt) {}
  Status bindError(int rc, int i);
  sqlite3* db_;
  sqlite3_stmt* stmt_;
  Status bind_status_;
};

// BEGIN IMMEDIATE (write) or BEGIN (read snapshot) ... COMMIT; rolls back when destroyed
// without commit().
class Transaction {
 public:
  enum class Kind { kWrite, kRead };
  static StatusOr<Transaction> begin(const Connection& connection, Kind kind);
  Transaction(Transaction&& other) noexcept : connection_(other.connection_) {
    other.connection_ = nullptr;
  }
  Transaction(const Transaction&) = delete;
  Transaction& operator=(const Transaction&) = delete;
  Transaction& operator=(Transaction&&) = delete;
  ~Transaction();
  Status commit();

 private:
  explicit Transaction(const Connection* connection) : connection_(connection) {}
  const Connection* connection_;
};

}  // namespace objdb::storage
