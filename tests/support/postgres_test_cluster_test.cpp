// The POSTGRES tests' cluster helper: fresh databases are distinct, empty and isolated from each
// other, their names are safe identifiers, and a missing cluster is a clean FAILED_PRECONDITION.
#include "tests/support/postgres_test_cluster.h"

#include <gtest/gtest.h>
#include <libpq-fe.h>

#include <cstdlib>
#include <memory>

#include "tests/support/temp_dir.h"

namespace objdb::testing {
namespace {

using PgConn = std::unique_ptr<PGconn, decltype(&PQfinish)>;

PgConn connect(const std::string& uri) { return PgConn(PQconnectdb(uri.c_str()), &PQfinish); }

// The single value `sql` returns; records a test failure and returns "<error>" when it fails.
std::string queryValue(PGconn* conn, const std::string& sql) {
  std::unique_ptr<PGresult, decltype(&PQclear)> result(PQexec(conn, sql.c_str()), &PQclear);
  if (PQresultStatus(result.get()) != PGRES_TUPLES_OK || PQntuples(result.get()) != 1) {
    ADD_FAILURE() << sql << ": " << PQerrorMessage(conn);
    return "<error>";
  }
  return PQgetvalue(result.get(), 0, 0);
}

void execute(PGconn* conn, const std::string& sql) {
  std::unique_ptr<PGresult, decltype(&PQclear)> result(PQexec(conn, sql.c_str()), &PQclear);
  EXPECT_EQ(PQresultStatus(result.get()), PGRES_COMMAND_OK) << sql << ": " << PQerrorMessage(conn);
}

constexpr char kPublicTables[] =
    "SELECT count(*) FROM information_schema.tables WHERE table_schema = 'public'";

TEST(PostgresTestCluster, FreshDatabasesAreDistinctAndEmpty) {
  StatusOr<std::string> first = freshPostgresDatabase("cluster_test");
  StatusOr<std::string> second = freshPostgresDatabase("cluster_test");
  ASSERT_TRUE(first.ok()) << first.status();
  ASSERT_TRUE(second.ok()) << second.status();
  EXPECT_NE(*first, *second);

  PgConn a = connect(*first);
  PgConn b = connect(*second);
  ASSERT_EQ(PQstatus(a.get()), CONNECTION_OK) << *first << ": " << PQerrorMessage(a.get());
  ASSERT_EQ(PQstatus(b.get()), CONNECTION_OK) << *second << ": " << PQerrorMessage(b.get());
  const std::string name_a = queryValue(a.get(), "SELECT current_database()");
  const std::string name_b = queryValue(b.get(), "SELECT current_database()");
  EXPECT_NE(name_a, name_b);
  EXPECT_EQ(name_a.rfind("cluster_test_", 0), 0u) << name_a;
  EXPECT_NE(name_a, "postgres");
  EXPECT_EQ(queryValue(a.get(), kPublicTables), "0");
  EXPECT_EQ(queryValue(b.get(), kPublicTables), "0");
}

TEST(PostgresTestCluster, TableInOneDatabaseIsInvisibleInTheOther) {
  StatusOr<std::string> first = freshPostgresDatabase("isolation");
  StatusOr<std::string> second = freshPostgresDatabase("isolation");
  ASSERT_TRUE(first.ok()) << first.status();
  ASSERT_TRUE(second.ok()) << second.status();
  PgConn a = connect(*first);
  PgConn b = connect(*second);
  ASSERT_EQ(PQstatus(a.get()), CONNECTION_OK) << PQerrorMessage(a.get());
  ASSERT_EQ(PQstatus(b.get()), CONNECTION_OK) << PQerrorMessage(b.get());

  execute(a.get(), "CREATE TABLE models (id integer PRIMARY KEY)");
  execute(a.get(), "INSERT INTO models VALUES (17)");
  EXPECT_EQ(queryValue(a.get(), "SELECT id FROM models"), "17");
  EXPECT_EQ(queryValue(a.get(), kPublicTables), "1");
  EXPECT_EQ(queryValue(b.get(), kPublicTables), "0");
  EXPECT_EQ(queryValue(b.get(), "SELECT to_regclass('public.models') IS NULL"), "t");
}

TEST(PostgresTestCluster, NameHintBecomesLowercaseSafeIdentifier) {
  StatusOr<std::string> uri = freshPostgresDatabase("Store Test-\"x\";DROP");
  ASSERT_TRUE(uri.ok()) << uri.status();
  PgConn conn = connect(*uri);
  ASSERT_EQ(PQstatus(conn.get()), CONNECTION_OK) << *uri << ": " << PQerrorMessage(conn.get());
  const std::string name = queryValue(conn.get(), "SELECT current_database()");
  EXPECT_EQ(name.rfind("store_test__x__drop_", 0), 0u) << name;
  EXPECT_EQ(name.find_first_not_of("abcdefghijklmnopqrstuvwxyz0123456789_"), std::string::npos)
      << name;
  // A hint that does not start with a letter still gives a valid name.
  StatusOr<std::string> digits = freshPostgresDatabase("42");
  ASSERT_TRUE(digits.ok()) << digits.status();
  EXPECT_NE(digits->find("/db_42_"), std::string::npos) << *digits;
}

TEST(PostgresTestCluster, UriWithDatabaseReplacesOnlyThePath) {
  EXPECT_EQ(postgresUriWithDatabase("postgresql://objdb@/postgres?host=/tmp/objdb-pg.a&port=5433",
                                    "t_1"),
            "postgresql://objdb@/t_1?host=/tmp/objdb-pg.a&port=5433");
  EXPECT_EQ(postgresUriWithDatabase("postgresql://u@localhost:5432/postgres", "t_1"),
            "postgresql://u@localhost:5432/t_1");
  EXPECT_EQ(postgresUriWithDatabase("postgres://u@h?sslmode=disable", "t_1"),
            "postgres://u@h/t_1?sslmode=disable");
  EXPECT_EQ(postgresUriWithDatabase("postgresql://h", "a b"), "postgresql://h/a%20b");
  EXPECT_EQ(postgresUriWithDatabase("host=/tmp port=1", "it's"), "host=/tmp port=1 dbname='it\\'s'");
}

TEST(PostgresTestCluster, MissingClusterIsFailedPreconditionSayingHowToStartIt) {
  const char* saved = std::getenv("OBJDB_TEST_POSTGRES_DIR");
  const std::string restore = saved == nullptr ? "" : saved;

  unsetenv("OBJDB_TEST_POSTGRES_DIR");
  StatusOr<std::string> unset = postgresClusterUri();
  EXPECT_EQ(unset.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_NE(unset.status().message().find("OBJDB_TEST_POSTGRES_DIR is not set"),
            std::string::npos)
      << unset.status();

  TempDir empty;  // no uri file: no cluster was started there
  setenv("OBJDB_TEST_POSTGRES_DIR", empty.path().c_str(), 1);
  StatusOr<std::string> missing = freshPostgresDatabase("never");
  EXPECT_EQ(missing.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_NE(missing.status().message().find("scripts/pg_test_cluster.sh start " +
                                            empty.path().string()),
            std::string::npos)
      << missing.status();

  // A uri file whose server is gone (a cluster stopped without its state cleaned up).
  ASSERT_TRUE(writeTextFile(empty / "uri", "postgresql://objdb@/postgres?host=" +
                                               empty.path().string() + "&port=5999\n"));
  StatusOr<std::string> gone = postgresClusterUri();
  EXPECT_EQ(gone.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_NE(gone.status().message().find("does not answer"), std::string::npos) << gone.status();

  if (saved == nullptr) {
    unsetenv("OBJDB_TEST_POSTGRES_DIR");
  } else {
    setenv("OBJDB_TEST_POSTGRES_DIR", restore.c_str(), 1);
  }
}

}  // namespace
}  // namespace objdb::testing
