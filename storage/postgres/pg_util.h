// A thin layer over libpq for the PostgreSQL store (postgres_store.h): typed parameters sent in
// binary (never SQL built from values), results read in binary, errors as Status by SQLSTATE
// class, a bounded pool of connections, and transactions retried on deadlock or serialization
// failure.
#pragma once

#include <libpq-fe.h>

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "core/common/status.h"

namespace objdb::storage::pg {

// The Status of a failed result: SQLSTATE 40001 (serialization failure) and 40P01 (deadlock) are
// ABORTED (the transaction may be retried), class 08 and a lost connection UNAVAILABLE, class 28
// UNAUTHENTICATED, 23505 ALREADY_EXISTS, other integrity violations (23) FAILED_PRECONDITION,
// 53 RESOURCE_EXHAUSTED, 57 (shutdown, cancel) UNAVAILABLE, anything else INTERNAL. The message
// names `context`, the SQLSTATE and PostgreSQL's message.
Status resultStatus(const PGresult* result, const PGconn* connection, std::string_view context);

// A statement's parameters, $1, $2, ... in the order added; each sent in binary with its type.
class Params {
 public:
  Params& add(int64_t value);           // int8
  Params& add(double value);            // float8
  Params& add(bool value);              // bool
  Params& text(std::string_view value); // text
  Params& bytes(std::string_view value);  // bytea
  Params& null();                       // NULL of unspecified type
  int size() const { return int(types_.size()); }

 private:
  friend class Connection;
  void push(Oid type, std::string value, bool is_null);
  std::vector<Oid> types_;
  std::vector<std::string> values_;
  std::vector<bool> nulls_;
};

// A statement's result rows, in binary. Column accessors check the column's type.
class Result {
 public:
  explicit Result(PGresult* result) : result_(result, &PQclear) {}
  int rows() const { return PQntuples(result_.get()); }
  // Rows an INSERT/UPDATE/DELETE touched.
  int64_t affected() const;
  bool isNull(int row, int column) const { return PQgetisnull(result_.get(), row, column) != 0; }
  int64_t integer(int row, int column) const;  // int2, int4, int8 (NULL: 0)
  double real(int row, int column) const;      // float4, float8 (NULL: 0)
  bool boolean(int row, int column) const;     // bool (NULL: false)
  std::string text(int row, int column) const; // text/varchar/name (NULL: "")
  std::string_view bytes(int row, int column) const;  // bytea: valid while the Result lives
  const PGresult* get() const { return result_.get(); }

 private:
  std::string_view raw(int row, int column) const;
  std::unique_ptr<PGresult, decltype(&PQclear)> result_;
};

class Connection {
 public:
  // Connects with libpq's connection string or URI; `connect_timeout_s` applies unless the target
  // sets its own. UNAVAILABLE when the server cannot be reached, UNAUTHENTICATED when it refuses
  // the credentials, INVALID_ARGUMENT for a malformed target. `describe` names the target in
  // messages (without its password).
  static StatusOr<Connection> open(const std::string& target, const std::string& describe,
                                   int connect_timeout_s);
  Connection(Connection&&) noexcept = default;
  Connection& operator=(Connection&&) noexcept = default;

  // One statement with parameters (extended protocol), results in binary.
  StatusOr<Result> exec(std::string_view sql, const Params& params, std::string_view context) const;
  StatusOr<Result> exec(std::string_view sql, std::string_view context) const {
    return exec(sql, Params(), context);
  }
  // Statements without parameters, several separated by ';' (simple protocol: migrations).
  Status script(std::string_view sql, std::string_view context) const;
  // Whether the connection is gone (the server closed it, the network failed).
  bool broken() const { return PQstatus(connection_.get()) != CONNECTION_OK; }
  PGconn* get() const { return connection_.get(); }

 private:
  explicit Connection(PGconn* connection) : connection_(connection, &PQfinish) {}
  std::unique_ptr<PGconn, decltype(&PQfinish)> connection_;
};

// Up to `size` idle connections to one database, opened on demand; a broken connection is not
// given back. Thread-safe.
class ConnectionPool {
 public:
  ConnectionPool(std::string target, std::string describe, int size, int connect_timeout_s)
      : target_(std::move(target)), describe_(std::move(describe)), size_(size),
        connect_timeout_s_(connect_timeout_s) {}

  class Lease {
   public:
    Lease(const ConnectionPool* pool, Connection connection)
        : pool_(pool), connection_(std::move(connection)) {}
    Lease(Lease&& other) noexcept = default;
    Lease& operator=(Lease&&) = delete;
    ~Lease();
    const Connection& operator*() const { return *connection_; }
    const Connection* operator->() const { return &*connection_; }

   private:
    const ConnectionPool* pool_;
    std::optional<Connection> connection_;
  };
  StatusOr<Lease> acquire() const;

  enum class Kind {
    kWrite,  // READ COMMITTED: the rows a write updates are locked until it commits
    kRead,   // REPEATABLE READ, READ ONLY: one snapshot
  };
  // Runs `body` in one transaction on one connection and commits it. A serialization failure or
  // deadlock (ABORTED, from the body or the commit) rolls back and runs the body again, at most
  // `max_retries` times (then UNAVAILABLE); each retry is counted in retries(). A transaction
  // whose BEGIN found the connection broken (a pooled connection of a restarted server), and a
  // read whose connection broke later, run once more on a new connection; a write that broke
  // after BEGIN does not (its outcome is unknown if COMMIT was lost): UNAVAILABLE.
  Status transact(Kind kind, int max_retries, std::string_view context,
                  const std::function<Status(const Connection&)>& body) const;
  int64_t retries() const { return retries_.load(); }
  const std::string& describe() const { return describe_; }

 private:
  std::string target_, describe_;
  int size_, connect_timeout_s_;
  mutable std::mutex mutex_;
  mutable std::vector<Connection> idle_;
  mutable std::atomic<int64_t> retries_{0};
};

}  // namespace objdb::storage::pg
