#include "tests/support/postgres_test_cluster.h"

#include <libpq-fe.h>
#include <unistd.h>

#include <atomic>
#include <cctype>
#include <cstdlib>
#include <fstream>
#include <memory>

namespace objdb::testing {
namespace {

constexpr char kDirVariable[] = "OBJDB_TEST_POSTGRES_DIR";

using PgConn = std::unique_ptr<PGconn, decltype(&PQfinish)>;
using PgResult = std::unique_ptr<PGresult, decltype(&PQclear)>;

std::string howToStart(const std::string& dir) {
  return absl::StrCat("run the test through ctest (fixture postgres_cluster), or start a cluster ",
                      "with `scripts/pg_test_cluster.sh start ", dir, "` and set ", kDirVariable,
                      "=", dir);
}

// Lowercase letters, digits and '_', starting with a letter, short enough to leave room in
// PostgreSQL's 63-byte identifiers for the pid and counter.
std::string safeIdentifier(const std::string& hint) {
  std::string name;
  for (unsigned char c : hint.substr(0, 40)) {
    name += (std::isalnum(c) && c < 0x80) ? static_cast<char>(std::tolower(c)) : '_';
  }
  if (name.empty() || !std::isalpha(static_cast<unsigned char>(name[0]))) name = "db_" + name;
  return name;
}

// Percent-encodes everything but RFC 3986's unreserved characters.
std::string percentEncode(const std::string& text) {
  std::string out;
  for (unsigned char c : text) {
    if (std::isalnum(c) && c < 0x80) {
      out += static_cast<char>(c);
    } else if (c == '-' || c == '.' || c == '_' || c == '~') {
      out += static_cast<char>(c);
    } else {
      out += absl::StrFormat("%%%02X", c);
    }
  }
  return out;
}

}  // namespace

StatusOr<std::string> postgresClusterUri() {
  const char* dir = std::getenv(kDirVariable);
  if (dir == nullptr || *dir == '\0') {
    return absl::FailedPreconditionError(
        absl::StrCat(kDirVariable, " is not set: ", howToStart("DIR")));
  }
  const std::string uri_path = absl::StrCat(dir, "/uri");
  std::ifstream in(uri_path);
  std::string uri;
  if (!in || !std::getline(in, uri) || uri.empty()) {
    return absl::FailedPreconditionError(
        absl::StrCat("no test cluster: cannot read ", uri_path, "; ", howToStart(dir)));
  }
  if (PQping(uri.c_str()) != PQPING_OK) {
    return absl::FailedPreconditionError(absl::StrCat(
        "the test cluster ", uri, " (from ", uri_path, ") does not answer; ", howToStart(dir)));
  }
  return uri;
}

StatusOr<std::string> freshPostgresDatabase(const std::string& name_hint) {
  OBJDB_ASSIGN_OR_RETURN(const std::string cluster_uri, postgresClusterUri());
  const char* keywords[] = {"dbname", "connect_timeout", nullptr};
  const char* values[] = {cluster_uri.c_str(), "10", nullptr};
  PgConn conn(PQconnectdbParams(keywords, values, /*expand_dbname=*/1), &PQfinish);
  if (PQstatus(conn.get()) != CONNECTION_OK) {
    return absl::UnavailableError(absl::StrCat("cannot connect to the test cluster ", cluster_uri,
                                               ": ", PQerrorMessage(conn.get())));
  }
  // Unique per process and call; a pid reused within one cluster's life (databases stay) only
  // costs a retry with the next counter value.
  static std::atomic<int> counter{0};
  const std::string base = absl::StrCat(safeIdentifier(name_hint), "_", getpid(), "_");
  for (int attempt = 0; attempt < 100; ++attempt) {
    const std::string name = absl::StrCat(base, counter.fetch_add(1));
    std::unique_ptr<char, decltype(&PQfreemem)> quoted(
        PQescapeIdentifier(conn.get(), name.c_str(), name.size()), &PQfreemem);
    if (quoted == nullptr) {
      return absl::InternalError(absl::StrCat("quoting database name ", name, ": ",
                                              PQerrorMessage(conn.get())));
    }
    PgResult result(PQexec(conn.get(), absl::StrCat("CREATE DATABASE ", quoted.get()).c_str()),
                    &PQclear);
    if (PQresultStatus(result.get()) == PGRES_COMMAND_OK) {
      return postgresUriWithDatabase(cluster_uri, name);
    }
    const char* sqlstate = PQresultErrorField(result.get(), PG_DIAG_SQLSTATE);
    if (sqlstate == nullptr || std::string(sqlstate) != "42P04") {  // 42P04: duplicate_database
      return absl::InternalError(absl::StrCat("CREATE DATABASE ", name, " in ", cluster_uri, ": ",
                                              PQerrorMessage(conn.get())));
    }
  }
  return absl::InternalError(
      absl::StrCat("CREATE DATABASE ", base, "N in ", cluster_uri, ": 100 names taken"));
}

std::string postgresUriWithDatabase(const std::string& uri, const std::string& dbname) {
  const size_t scheme_end = uri.find("://");
  if (scheme_end == std::string::npos) {
    // A keyword/value conninfo string: a later keyword overrides an earlier one.
    std::string quoted;
    for (char c : dbname) {
      if (c == '\\' || c == '\'') quoted += '\\';
      quoted += c;
    }
    return absl::StrCat(uri, " dbname='", quoted, "'");
  }
  const std::string encoded = percentEncode(dbname);
  // The authority (user@host:port) ends at the path's '/' or at the query's '?'.
  const size_t path_start = uri.find_first_of("/?", scheme_end + 3);
  if (path_start == std::string::npos) return absl::StrCat(uri, "/", encoded);
  const size_t query_start = uri.find('?', path_start);
  const std::string query = query_start == std::string::npos ? "" : uri.substr(query_start);
  return absl::StrCat(uri.substr(0, path_start), "/", encoded, query);
}

}  // namespace objdb::testing
