#include "storage/postgres/pg_util.h"

#include <endian.h>

#include <algorithm>
#include <bit>
#include <chrono>
#include <cstring>
#include <random>
#include <thread>

#include "absl/strings/match.h"
#include "absl/strings/str_format.h"
#include "absl/strings/strip.h"
#include "core/common/logging.h"

namespace objdb::storage::pg {
namespace {

// Type OIDs (PostgreSQL's pg_type.dat; stable across versions).
constexpr Oid kBool = 16, kBytea = 17, kName = 19, kInt8 = 20, kInt2 = 21, kInt4 = 23,
              kText = 25, kFloat4 = 700, kFloat8 = 701, kVarchar = 1043;

std::string trimmed(const char* message) {
  return std::string(absl::StripTrailingAsciiWhitespace(message == nullptr ? "" : message));
}

void logNotice(void*, const char* message) {
  logger("storage")->debug("postgres: {}", trimmed(message));
}

// PostgreSQL's binary format: numbers big-endian.
std::string bigEndianBytes(uint64_t value) {
  const uint64_t be = htobe64(value);
  return std::string(reinterpret_cast<const char*>(&be), sizeof(be));
}

// The unsigned big-endian number of type U at the start of `v` (zero-filled when shorter).
template <typename U>
U fromBigEndian(std::string_view v) {
  U be = 0;
  std::memcpy(&be, v.data(), std::min(v.size(), sizeof(be)));
  if constexpr (sizeof(U) == 8) {
    return be64toh(be);
  } else if constexpr (sizeof(U) == 4) {
    return be32toh(be);
  } else {
    static_assert(sizeof(U) == 2);
    return be16toh(be);
  }
}

}  // namespace

Status resultStatus(const PGresult* result, const PGconn* connection, std::string_view context) {
  if (result == nullptr) {
    return absl::UnavailableError(absl::StrFormat(
        "%s: no answer from PostgreSQL: %s", context, trimmed(PQerrorMessage(connection))));
  }
  const ExecStatusType status = PQresultStatus(result);
  if (status == PGRES_COMMAND_OK || status == PGRES_TUPLES_OK) return absl::OkStatus();
  const char* state = PQresultErrorField(result, PG_DIAG_SQLSTATE);
  const std::string sqlstate = state == nullptr ? "" : state;
  std::string message = trimmed(PQresultErrorField(result, PG_DIAG_MESSAGE_PRIMARY));
  if (message.empty()) message = trimmed(PQresultErrorMessage(result));
  if (message.empty()) message = trimmed(PQerrorMessage(connection));
  const std::string text = absl::StrFormat("%s: PostgreSQL %s%s", context,
                                           sqlstate.empty() ? "" : "(" + sqlstate + ") ", message);
  if (sqlstate == "40001" || sqlstate == "40P01") return absl::AbortedError(text);
  if (sqlstate == "23505") return absl::AlreadyExistsError(text);
  if (sqlstate.empty() || absl::StartsWith(sqlstate, "08") || absl::StartsWith(sqlstate, "57")) {
    return absl::UnavailableError(text);
  }
  if (absl::StartsWith(sqlstate, "28")) return absl::UnauthenticatedError(text);
  if (absl::StartsWith(sqlstate, "23")) return absl::FailedPreconditionError(text);
  if (absl::StartsWith(sqlstate, "53")) return absl::ResourceExhaustedError(text);
  return absl::InternalError(text);
}

void Params::push(Oid type, std::string value, bool is_null) {
  types_.push_back(type);
  values_.push_back(std::move(value));
  nulls_.push_back(is_null);
}

Params& Params::add(int64_t value) {
  push(kInt8, bigEndianBytes(uint64_t(value)), false);
  return *this;
}

Params& Params::add(double value) {
  push(kFloat8, bigEndianBytes(std::bit_cast<uint64_t>(value)), false);
  return *this;
}

Params& Params::add(bool value) {
  push(kBool, std::string(1, value ? '\1' : '\0'), false);
  return *this;
}

Params& Params::text(std::string_view value) {
  push(kText, std::string(value), false);
  return *this;
}

Params& Params::bytes(std::string_view value) {
  push(kBytea, std::string(value), false);
  return *this;
}

Params& Params::null() {
  push(0, std::string(), true);
  return *this;
}

int64_t Result::affected() const {
  const char* tuples = PQcmdTuples(result_.get());
  return (tuples == nullptr || *tuples == '\0') ? 0 : std::strtoll(tuples, nullptr, 10);
}

std::string_view Result::raw(int row, int column) const {
  return std::string_view(PQgetvalue(result_.get(), row, column),
                          size_t(PQgetlength(result_.get(), row, column)));
}

int64_t Result::integer(int row, int column) const {
  if (isNull(row, column)) return 0;
  const std::string_view v = raw(row, column);
  switch (PQftype(result_.get(), column)) {
    case kInt8: return int64_t(fromBigEndian<uint64_t>(v));
    case kInt4: return int32_t(fromBigEndian<uint32_t>(v));
    case kInt2: return int16_t(fromBigEndian<uint16_t>(v));
    case kBool: return v.empty() ? 0 : int64_t(v[0] != 0);
    default: return 0;
  }
}

double Result::real(int row, int column) const {
  if (isNull(row, column)) return 0.0;
  const std::string_view v = raw(row, column);
  switch (PQftype(result_.get(), column)) {
    case kFloat8: return std::bit_cast<double>(fromBigEndian<uint64_t>(v));
    case kFloat4: return std::bit_cast<float>(fromBigEndian<uint32_t>(v));
    default: return double(integer(row, column));
  }
}

bool Result::boolean(int row, int column) const { return integer(row, column) != 0; }

std::string Result::text(int row, int column) const {
  if (isNull(row, column)) return std::string();
  const Oid type = PQftype(result_.get(), column);
  if (type != kText && type != kVarchar && type != kName && type != kBytea) return std::string();
  return std::string(raw(row, column));
}

std::string_view Result::bytes(int row, int column) const {
  if (isNull(row, column)) return std::string_view();
  return raw(row, column);
}

StatusOr<Connection> Connection::open(const std::string& target, const std::string& describe,
                                      int connect_timeout_s) {
  char* parse_error = nullptr;
  PQconninfoOption* parsed = PQconninfoParse(target.c_str(), &parse_error);
  if (parsed == nullptr) {
    const std::string why = trimmed(parse_error);
    PQfreemem(parse_error);
    return absl::InvalidArgumentError(
        absl::StrFormat("%s is not a PostgreSQL connection URI: %s", describe, why));
  }
  PQconninfoFree(parsed);
  const std::string timeout = std::to_string(connect_timeout_s);
  // Later keywords win: the target's own connect_timeout overrides ours.
  const char* keywords[] = {"connect_timeout", "fallback_application_name", "dbname", nullptr};
  const char* values[] = {timeout.c_str(), "objdb", target.c_str(), nullptr};
  PGconn* raw = PQconnectdbParams(keywords, values, /*expand_dbname=*/1);
  if (raw == nullptr) return absl::ResourceExhaustedError("libpq could not allocate a connection");
  Connection connection(raw);
  if (PQstatus(raw) != CONNECTION_OK) {
    const std::string why = trimmed(PQerrorMessage(raw));
    const std::string text = absl::StrFormat("connecting to %s: %s", describe, why);
    if (PQconnectionNeedsPassword(raw) || absl::StrContains(why, "authentication failed") ||
        absl::StrContains(why, "no password supplied") ||
        absl::StrContains(why, "no pg_hba.conf entry") ||
        // A role that does not exist is refused credentials, as a wrong password is.
        (absl::StrContains(why, "role \"") && absl::StrContains(why, "does not exist"))) {
      return absl::UnauthenticatedError(text);
    }
    // The database named by the URI is not there (create it, or fix the name).
    if (absl::StrContains(why, "database \"") && absl::StrContains(why, "does not exist")) {
      return absl::NotFoundError(text);
    }
    return absl::UnavailableError(text);
  }
  PQsetNoticeProcessor(raw, &logNotice, nullptr);
  return connection;
}

StatusOr<Result> Connection::exec(std::string_view sql, const Params& params,
                                  std::string_view context) const {
  const int n = params.size();
  std::vector<const char*> values(n);
  std::vector<int> lengths(n), formats(n, 1);
  for (int i = 0; i < n; ++i) {
    values[i] = params.nulls_[i] ? nullptr : params.values_[i].data();
    lengths[i] = int(params.values_[i].size());
  }
  const std::string statement(sql);
  Result result(PQexecParams(connection_.get(), statement.c_str(), n, params.types_.data(),
                             values.data(), lengths.data(), formats.data(), /*resultFormat=*/1));
  OBJDB_RETURN_IF_ERROR(resultStatus(result.get(), connection_.get(), context));
  return result;
}

Status Connection::script(std::string_view sql, std::string_view context) const {
  const std::string statements(sql);
  Result result(PQexec(connection_.get(), statements.c_str()));
  return resultStatus(result.get(), connection_.get(), context);
}

ConnectionPool::Lease::~Lease() {
  if (!connection_ || pool_ == nullptr) return;
  if (connection_->broken() || PQtransactionStatus(connection_->get()) != PQTRANS_IDLE) return;
  std::lock_guard lock(pool_->mutex_);
  if (pool_->idle_.size() < size_t(pool_->size_)) pool_->idle_.push_back(std::move(*connection_));
}

StatusOr<ConnectionPool::Lease> ConnectionPool::acquire() const {
  {
    std::lock_guard lock(mutex_);
    while (!idle_.empty()) {
      Connection c = std::move(idle_.back());
      idle_.pop_back();
      if (!c.broken()) return Lease(this, std::move(c));
    }
  }
  OBJDB_ASSIGN_OR_RETURN(Connection c, Connection::open(target_, describe_, connect_timeout_s_));
  return Lease(this, std::move(c));
}

Status ConnectionPool::transact(Kind kind, int max_retries, std::string_view context,
                                const std::function<Status(const Connection&)>& body) const {
  const char* begin = kind == Kind::kWrite
                          ? "BEGIN ISOLATION LEVEL READ COMMITTED"
                          : "BEGIN ISOLATION LEVEL REPEATABLE READ READ ONLY";
  bool reconnected = false;
  thread_local std::minstd_rand jitter(std::random_device{}());
  for (int attempt = 0;; ++attempt) {
    OBJDB_ASSIGN_OR_RETURN(Lease lease, acquire());
    Status status = lease->exec(begin, context).status();
    if (!status.ok() && lease->broken() && !reconnected) {
      // A pooled connection the server closed meanwhile (a restart): nothing ran yet, so even a
      // write may go again on a new connection.
      reconnected = true;
      continue;
    }
    if (status.ok()) status = body(*lease);
    if (status.ok()) status = lease->exec("COMMIT", context).status();
    if (status.ok()) return status;
    if (!lease->broken() && PQtransactionStatus(lease->get()) != PQTRANS_IDLE) {
      (void)lease->exec("ROLLBACK", context);
    }
    if (absl::IsAborted(status)) {
      if (attempt >= max_retries) {
        return absl::UnavailableError(absl::StrFormat(
            "%s (still conflicting after %d retries)", status.message(), max_retries));
      }
      retries_.fetch_add(1);
      // Back off a little, growing, with jitter, so that the conflicting writers part.
      const int cap_ms = std::min(100, 1 << std::min(attempt, 6));
      std::this_thread::sleep_for(std::chrono::milliseconds(1 + int(jitter() % unsigned(cap_ms))));
      continue;
    }
    if (kind == Kind::kRead && lease->broken() && !reconnected) {
      reconnected = true;
      continue;
    }
    return status;
  }
}

}  // namespace objdb::storage::pg
