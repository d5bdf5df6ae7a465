#include "storage/sqlite/sqlite_util.h"

#include <algorithm>
#include <initializer_list>

#include "absl/strings/str_format.h"

namespace objdb::storage {

Status sqliteStatus(int rc, sqlite3* db, std::string_view context) {
  if (rc == SQLITE_OK || rc == SQLITE_DONE || rc == SQLITE_ROW) return absl::OkStatus();
  const std::string message = absl::StrFormat(
      "%s: %s (%s)", context, db != nullptr ? sqlite3_errmsg(db) : sqlite3_errstr(rc),
      sqlite3_errstr(rc));
  // By the primary result code.
  const auto any = [primary = rc & 0xff](std::initializer_list<int> codes) {
    return std::find(codes.begin(), codes.end(), primary) != codes.end();
  };
  if (any({SQLITE_BUSY, SQLITE_LOCKED, SQLITE_IOERR, SQLITE_CANTOPEN, SQLITE_PROTOCOL})) {
    return absl::UnavailableError(message);
  }
  if (any({SQLITE_FULL, SQLITE_NOMEM, SQLITE_TOOBIG})) return absl::ResourceExhaustedError(message);
  if (any({SQLITE_CORRUPT, SQLITE_NOTADB})) return absl::DataLossError(message);
  if (any({SQLITE_CONSTRAINT})) return absl::FailedPreconditionError(message);
  if (any({SQLITE_READONLY, SQLITE_PERM, SQLITE_AUTH})) return absl::PermissionDeniedError(message);
  return absl::InternalError(message);
}

StatusOr<Connection> Connection::open(const std::string& path, const ConnectionOptions& options) {
  int flags = SQLITE_OPEN_NOMUTEX;  // one connection per thread; the store serialises writes
  if (options.read_only) {
    flags |= SQLITE_OPEN_READONLY;
  } else {
    flags |= SQLITE_OPEN_READWRITE;
    if (options.create) flags |= SQLITE_OPEN_CREATE;
  }
  sqlite3* db = nullptr;
  const int rc = sqlite3_open_v2(path.c_str(), &db, flags, nullptr);
  Connection connection(db);  // closes on every return below
  if (rc != SQLITE_OK) {
    return sqliteStatus(rc, db, absl::StrFormat("opening %s", path));
  }
  sqlite3_extended_result_codes(db, 1);
  // Hardening (security.html): no schema-triggered functions, defensive mode.
  sqlite3_db_config(db, SQLITE_DBCONFIG_DEFENSIVE, 1, nullptr);
  sqlite3_db_config(db, SQLITE_DBCONFIG_TRUSTED_SCHEMA, 0, nullptr);
  sqlite3_busy_timeout(db, options.busy_timeout_ms);
  if (options.synchronous != "FULL" && options.synchronous != "NORMAL") {
    return absl::InvalidArgumentError(absl::StrFormat(
        "storage: synchronous must be FULL or NORMAL, got '%s'", options.synchronous));
  }
  OBJDB_RETURN_IF_ERROR(connection.exec(
      absl::StrFormat("PRAGMA foreign_keys=ON; PRAGMA cell_size_check=ON; PRAGMA synchronous=%s;",
                      options.synchronous),
      absl::StrFormat("configuring %s", path)));
  return connection;
}

Connection& Connection::operator=(Connection&& other) noexcept {
  if (this != &other) {
    if (db_ != nullptr) sqlite3_close_v2(db_);
    db_ = other.db_;
    other.db_ = nullptr;
  }
  return *this;
}

Connection::~Connection() {
  if (db_ != nullptr) sqlite3_close_v2(db_);
}

Status Connection::exec(std::string_view sql, std::string_view context) const {
  char* error = nullptr;
  const int rc = sqlite3_exec(db_, std::string(sql).c_str(), nullptr, nullptr, &error);
  if (error != nullptr) sqlite3_free(error);
  return sqliteStatus(rc, db_, context);
}

StatusOr<int64_t> Connection::queryInt(std::string_view sql, std::string_view context) const {
  auto statement = Statement::prepare(*this, sql);
  if (!statement.ok()) return annotate(statement.status(), std::string(context));
  auto row = statement->step();
  if (!row.ok()) return annotate(row.status(), std::string(context));
  if (!*row) return absl::InternalError(absl::StrFormat("%s: no result", context));
  return statement->columnInt(0);
}

StatusOr<Statement> Statement::prepare(const Connection& connection, std::string_view sql) {
  sqlite3_stmt* stmt = nullptr;
  const int rc = sqlite3_prepare_v2(connection.get(), sql.data(), int(sql.size()), &stmt, nullptr);
  if (rc != SQLITE_OK) {
    if (stmt != nullptr) sqlite3_finalize(stmt);
    return sqliteStatus(rc, connection.get(), absl::StrFormat("preparing \"%s\"", sql));
  }
  return Statement(connection.get(), stmt);
}

Statement::~Statement() {
  if (stmt_ != nullptr) sqlite3_finalize(stmt_);
}

Status Statement::bindError(int rc, int i) {
  if (rc != SQLITE_OK && bind_status_.ok()) {
    bind_status_ = sqliteStatus(rc, db_, absl::StrFormat("binding parameter %d", i));
  }
  return bind_status_;
}

Statement& Statement::bind(int i, int64_t value) {
  (void)bindError(sqlite3_bind_int64(stmt_, i, value), i);
  return *this;
}
Statement& Statement::bind(int i, double value) {
  (void)bindError(sqlite3_bind_double(stmt_, i, value), i);
  return *this;
}
Statement& Statement::bind(int i, std::string_view text) {
  (void)bindError(sqlite3_bind_text64(stmt_, i, text.data(), text.size(), SQLITE_TRANSIENT, SQLITE_UTF8),
            i);
  return *this;
}
Statement& Statement::bindBlob(int i, std::string_view bytes) {
  // A zero-length blob must still be a BLOB, not NULL: pass a non-null pointer.
  static const char kEmpty = 0;
  (void)bindError(sqlite3_bind_blob64(stmt_, i, bytes.empty() ? &kEmpty : bytes.data(), bytes.size(),
                                SQLITE_TRANSIENT),
            i);
  return *this;
}
Statement& Statement::bindNull(int i) {
  (void)bindError(sqlite3_bind_null(stmt_, i), i);
  return *this;
}

StatusOr<bool> Statement::step() {
  OBJDB_RETURN_IF_ERROR(bind_status_);
  const int rc = sqlite3_step(stmt_);
  if (rc == SQLITE_ROW) return true;
  if (rc == SQLITE_DONE) return false;
  return sqliteStatus(rc, db_, absl::StrFormat("running \"%s\"", sqlite3_sql(stmt_)));
}

Status Statement::run() {
  while (true) {
    OBJDB_ASSIGN_OR_RETURN(const bool row, step());
    if (!row) return absl::OkStatus();
  }
}

Status Statement::reset() {
  sqlite3_reset(stmt_);
  sqlite3_clear_bindings(stmt_);
  bind_status_ = absl::OkStatus();
  return absl::OkStatus();
}

std::string Statement::columnText(int i) const {
  const auto* text = sqlite3_column_text(stmt_, i);
  return text == nullptr ? std::string() : std::string(reinterpret_cast<const char*>(text));
}

std::string_view Statement::columnBlob(int i) const {
  const void* data = sqlite3_column_blob(stmt_, i);
  const int n = sqlite3_column_bytes(stmt_, i);
  if (data == nullptr || n <= 0) return {};
  return {static_cast<const char*>(data), size_t(n)};
}

StatusOr<Transaction> Transaction::begin(const Connection& connection, Kind kind) {
  OBJDB_RETURN_IF_ERROR(connection.exec(kind == Kind::kWrite ? "BEGIN IMMEDIATE" : "BEGIN",
                                        "starting a transaction"));
  return Transaction(&connection);
}

Transaction::~Transaction() {
  if (connection_ != nullptr) (void)connection_->exec("ROLLBACK", "rolling back");
}

Status Transaction::commit() {
  if (connection_ == nullptr) return absl::InternalError("transaction already finished");
  const Connection* connection = connection_;
  const Status status = connection->exec("COMMIT", "committing");
  if (status.ok()) connection_ = nullptr;  // on failure the destructor rolls back
  return status;
}

}  // namespace objdb::storage
