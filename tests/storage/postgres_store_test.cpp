// What only PostgresStore (storage/postgres/postgres_store.h) does, beyond the Store conformance
// suite: the schema's bookkeeping and its refusals, servers opening and writing at once on one
// database, connection errors without passwords, damage found per row, and backups as pg_dump
// archives that pg_restore brings back. Every test gets new, empty databases of the throwaway
// cluster (tests/support/postgres_test_cluster.h); out-of-band SQL goes through raw libpq, as
// another program or a person would.
#include "storage/postgres/postgres_store.h"

#include <libpq-fe.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <iterator>
#include <iostream>
#include <latch>
#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_split.h"
#include "storage/postgres/pg_schema.h"
#include "tests/storage/store_fixtures.h"
#include "tests/support/postgres_test_cluster.h"
#include "tests/support/temp_dir.h"

namespace objdb::storage {
namespace {

using objdb::testing::diffLayers;
using objdb::testing::diffModels;
using objdb::testing::makeRawSegment;
using objdb::testing::makeStoreModel;
using objdb::testing::TempDir;
using ::testing::HasSubstr;
using ::testing::IsEmpty;
using ::testing::Not;

int latestSchemaVersion() { return pg::schemaMigrations().back().version; }

// A new, empty database of the test cluster. Without one the test fails (it is not skipped: CI
// runs the cluster) and the result is empty.
std::string freshDatabase(const std::string& hint) {
  StatusOr<std::string> uri = objdb::testing::freshPostgresDatabase(hint);
  if (uri.ok()) return *uri;
  ADD_FAILURE() << "no fresh test database: " << uri.status();
  return "";
}

std::unique_ptr<PostgresStore> openStore(const std::string& uri,
                                         const PostgresStoreOptions& options = {}) {
  auto store = PostgresStore::open(uri, options);
  EXPECT_TRUE(store.ok()) << store.status();
  return store.ok() ? std::move(*store) : nullptr;
}

// SQL on a database outside any store, in libpq's text format.
class RawSql {
 public:
  explicit RawSql(const std::string& uri) : connection_(PQconnectdb(uri.c_str()), &PQfinish) {
    EXPECT_EQ(PQstatus(connection_.get()), CONNECTION_OK) << PQerrorMessage(connection_.get());
  }
  // Runs `sql` (statements separated by ';'). The last statement's first value, or for a command
  // the number of rows it touched; "" and a failed test on an error.
  std::string run(const std::string& sql) {
    std::unique_ptr<PGresult, decltype(&PQclear)> r(PQexec(connection_.get(), sql.c_str()),
                                                    &PQclear);
    const ExecStatusType status = PQresultStatus(r.get());
    if (status == PGRES_TUPLES_OK) {
      return PQntuples(r.get()) > 0 ? std::string(PQgetvalue(r.get(), 0, 0)) : std::string();
    }
    if (status == PGRES_COMMAND_OK) return PQcmdTuples(r.get());
    ADD_FAILURE() << sql << ": " << PQresultErrorMessage(r.get());
    return "";
  }
  std::string tableCount() {
    return run("SELECT COUNT(*) FROM information_schema.tables "
               "WHERE table_schema = current_schema()");
  }
  bool hasTable(const std::string& table) {
    return run("SELECT to_regclass('" + table + "') IS NOT NULL") == "t";
  }
  std::string meta(const std::string& key) {
    return run("SELECT value FROM objdb_meta WHERE key = '" + key + "'");
  }

 private:
  std::unique_ptr<PGconn, decltype(&PQfinish)> connection_;
};

bool isExecutable(const std::filesystem::path& path) { return ::access(path.c_str(), X_OK) == 0; }

bool hasClientTools(const std::filesystem::path& dir) {
  return isExecutable(dir / "pg_dump") && isExecutable(dir / "pg_restore");
}

// The directory of pg_dump and pg_restore: the newest /usr/lib/postgresql/N/bin (the test
// cluster's server is the newest there, scripts/pg_test_cluster.sh, and pg_dump refuses servers
// newer than itself), else the first PATH directory holding both; empty when none does.
std::string postgresClientDir() {
  std::error_code ec;
  int best_version = -1;
  std::string best;
  for (const auto& entry : std::filesystem::directory_iterator("/usr/lib/postgresql", ec)) {
    int version = 0;
    if (!absl::SimpleAtoi(entry.path().filename().string(), &version)) continue;
    if (version > best_version && hasClientTools(entry.path() / "bin")) {
      best_version = version;
      best = (entry.path() / "bin").string();
    }
  }
  if (!best.empty()) return best;
  const char* path = std::getenv("PATH");
  for (const absl::string_view dir : absl::StrSplit(path == nullptr ? "" : path, ':')) {
    if (!dir.empty() && hasClientTools(std::filesystem::path(std::string(dir)))) {
      return std::string(dir);
    }
  }
  return "";
}

std::string shellQuote(const std::string& text) {
  std::string out = "'";
  for (const char c : text) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return out + "'";
}

// Runs `command` through /bin/sh: its exit status and what it printed on stdout and stderr.
std::pair<int, std::string> runShell(const std::string& command) {
  FILE* pipe = ::popen((command + " 2>&1").c_str(), "r");
  if (pipe == nullptr) return {-1, "popen failed"};
  std::string output;
  char buffer[4096];
  size_t n = 0;
  while ((n = std::fread(buffer, 1, sizeof(buffer), pipe)) > 0) output.append(buffer, n);
  const int status = ::pclose(pipe);
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, output};
}

TEST(PostgresStore, ANewDatabaseGetsTheCurrentSchema) {
  const std::string uri = freshDatabase("pg_new_schema");
  ASSERT_FALSE(uri.empty());
  RawSql sql(uri);
  ASSERT_FALSE(sql.hasTable("objdb_meta"));
  {
    auto store = openStore(uri);
    ASSERT_NE(store, nullptr);
    EXPECT_EQ(store->schemaVersion(), latestSchemaVersion());
    EXPECT_EQ(store->stats().value().schema_version, latestSchemaVersion());
    EXPECT_TRUE(store->modelIds().value().empty());
  }
  EXPECT_EQ(sql.meta("application"), "objdb");
  EXPECT_EQ(sql.meta("schema_version"), std::to_string(latestSchemaVersion()));
  EXPECT_TRUE(sql.hasTable("models"));
  const std::string tables = sql.tableCount();

  // Reopening finds the schema current: no migration runs, nothing is added.
  auto again = openStore(uri);
  ASSERT_NE(again, nullptr);
  EXPECT_EQ(again->schemaVersion(), latestSchemaVersion());
  EXPECT_EQ(sql.run("SELECT COUNT(*) FROM objdb_meta"), "2");
  EXPECT_EQ(sql.meta("schema_version"), std::to_string(latestSchemaVersion()));
  EXPECT_EQ(sql.tableCount(), tables);
}

TEST(PostgresStore, ADatabaseOfAnotherApplicationIsRefusedUntouched) {
  const std::string uri = freshDatabase("pg_foreign_tables");
  ASSERT_FALSE(uri.empty());
  RawSql sql(uri);
  sql.run("CREATE TABLE foo (x INTEGER); INSERT INTO foo VALUES (7)");
  auto refused = PostgresStore::open(uri);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().code(), absl::StatusCode::kFailedPrecondition) << refused.status();
  EXPECT_THAT(refused.status().message(), HasSubstr("not objdb's"));
  EXPECT_EQ(sql.tableCount(), "1");
  EXPECT_FALSE(sql.hasTable("objdb_meta"));
  EXPECT_EQ(sql.run("SELECT string_agg(x::text, ',') FROM foo"), "7");

  // An objdb_meta table, but of another application.
  const std::string other_uri = freshDatabase("pg_foreign_meta");
  ASSERT_FALSE(other_uri.empty());
  RawSql other(other_uri);
  other.run(
      "CREATE TABLE objdb_meta (key TEXT PRIMARY KEY, value TEXT NOT NULL); "
      "INSERT INTO objdb_meta VALUES ('application', 'other'), ('schema_version', '1')");
  auto foreign = PostgresStore::open(other_uri);
  ASSERT_FALSE(foreign.ok());
  EXPECT_EQ(foreign.status().code(), absl::StatusCode::kFailedPrecondition) << foreign.status();
  EXPECT_THAT(foreign.status().message(), HasSubstr("another application (application 'other')"));
  EXPECT_EQ(other.tableCount(), "1");
  EXPECT_EQ(other.meta("application"), "other");
  EXPECT_EQ(other.meta("schema_version"), "1");
}

TEST(PostgresStore, ANewerSchemaIsRefusedUntouched) {
  const std::string uri = freshDatabase("pg_newer_schema");
  ASSERT_FALSE(uri.empty());
  { ASSERT_NE(openStore(uri), nullptr); }
  RawSql sql(uri);
  EXPECT_EQ(sql.run("UPDATE objdb_meta SET value = '999' WHERE key = 'schema_version'"), "1");
  const std::string tables = sql.tableCount();
  auto refused = PostgresStore::open(uri);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().code(), absl::StatusCode::kFailedPrecondition) << refused.status();
  EXPECT_THAT(refused.status().message(), HasSubstr("schema version 999, newer"));
  EXPECT_THAT(refused.status().message(),
              HasSubstr(absl::StrFormat("(up to %d)", latestSchemaVersion())));
  EXPECT_EQ(sql.meta("schema_version"), "999");
  EXPECT_EQ(sql.tableCount(), tables);
}

// The advisory lock serialises schema preparation: without it, the second server's CREATE TABLE
// would fail on the first one's.
TEST(PostgresStore, ServersOpeningAtOnceMigrateOnce) {
  const std::string uri = freshDatabase("pg_open_at_once");
  ASSERT_FALSE(uri.empty());
  constexpr int kServers = 4;
  std::latch start(kServers);
  std::vector<Status> statuses(kServers);
  std::vector<std::unique_ptr<PostgresStore>> stores(kServers);
  std::vector<std::thread> threads;
  for (int k = 0; k < kServers; ++k) {
    threads.emplace_back([&, k] {
      start.arrive_and_wait();
      auto store = PostgresStore::open(uri);
      statuses[k] = store.status();
      if (store.ok()) stores[k] = std::move(*store);
    });
  }
  for (auto& thread : threads) thread.join();
  for (int k = 0; k < kServers; ++k) {
    ASSERT_TRUE(statuses[k].ok()) << "server " << k << ": " << statuses[k];
    EXPECT_EQ(stores[k]->schemaVersion(), latestSchemaVersion()) << "server " << k;
  }
  RawSql sql(uri);
  EXPECT_EQ(sql.run("SELECT COUNT(*) FROM objdb_meta"), "2");
  EXPECT_EQ(sql.meta("schema_version"), std::to_string(latestSchemaVersion()));
  // All of them work on the one schema.
  const auto id = stores[0]->addModel(makeStoreModel(1, 1));
  ASSERT_TRUE(id.ok()) << id.status();
  for (int k = 0; k < kServers; ++k) {
    EXPECT_TRUE(stores[k]->model(*id).ok()) << "server " << k;
  }
}

TEST(PostgresStore, AMissingDatabaseIsNotFoundAndAnUnknownRoleIsRefused) {
  const auto cluster = objdb::testing::postgresClusterUri();
  ASSERT_TRUE(cluster.ok()) << cluster.status();
  auto missing =
      PostgresStore::open(objdb::testing::postgresUriWithDatabase(*cluster, "no_such_database"));
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().code(), absl::StatusCode::kNotFound) << missing.status();
  EXPECT_THAT(missing.status().message(), HasSubstr("no_such_database"));
  std::string stranger = *cluster;
  const size_t at = stranger.find("objdb@");
  ASSERT_NE(at, std::string::npos) << stranger;
  stranger.replace(at, 6, "no_such_role@");
  auto refused = PostgresStore::open(stranger);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().code(), absl::StatusCode::kUnauthenticated) << refused.status();
  EXPECT_THAT(refused.status().message(), HasSubstr("no_such_role"));
}

TEST(PostgresStore, AnUnreachableServerIsUnavailable) {
  auto plain =
      PostgresStore::open("postgresql://objdb@/x?host=/nonexistent-objdb-dir&connect_timeout=2");
  ASSERT_FALSE(plain.ok());
  EXPECT_EQ(plain.status().code(), absl::StatusCode::kUnavailable) << plain.status();
  EXPECT_THAT(plain.status().message(), HasSubstr("/nonexistent-objdb-dir"));

  // Passwords, in the userinfo or as a parameter, stay out of the message.
  for (const char* uri :
       {"postgresql://objdb:secret@/x?host=/nonexistent-objdb-dir&connect_timeout=2",
        "postgresql://objdb@/x?host=/nonexistent-objdb-dir&password=secret&connect_timeout=2"}) {
    auto opened = PostgresStore::open(uri);
    ASSERT_FALSE(opened.ok()) << uri;
    EXPECT_EQ(opened.status().code(), absl::StatusCode::kUnavailable) << uri;
    EXPECT_THAT(opened.status().message(), Not(HasSubstr("secret"))) << uri;
    EXPECT_THAT(opened.status().message(), HasSubstr("***")) << uri;
    EXPECT_THAT(opened.status().message(), HasSubstr("/nonexistent-objdb-dir")) << uri;
  }
}

TEST(PostgresStore, RedactPostgresUriHidesPasswords) {
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"postgresql://objdb:secret@db.example.org:5432/objdb",
       "postgresql://objdb:***@db.example.org:5432/objdb"},
      {"postgres://objdb:s%40cret@db/objdb?sslmode=require",
       "postgres://objdb:***@db/objdb?sslmode=require"},
      {"postgresql://objdb@db/objdb?password=secret", "postgresql://objdb@db/objdb?password=***"},
      {"postgresql://db/objdb?sslmode=require&password=secret&application_name=x",
       "postgresql://db/objdb?sslmode=require&password=***&application_name=x"},
      {"postgresql://objdb:secret@db/objdb?password=secret",
       "postgresql://objdb:***@db/objdb?password=***"},
      // The passphrase of a client key (sslpassword), in a URI and in keyword/value form.
      {"postgresql://objdb@db/objdb?sslcert=c.pem&sslkey=k.pem&sslpassword=secret",
       "postgresql://objdb@db/objdb?sslcert=c.pem&sslkey=k.pem&sslpassword=***"},
      {"host=db dbname=objdb password=secret sslpassword = 'sec ret'",
       "host=db dbname=objdb password=*** sslpassword = ***"},
      {"password='se\\'cret' host=db", "password=*** host=db"},
      // Nothing to hide: unchanged (a port is no password).
      {"postgresql://objdb@/objdb?host=/tmp/objdb-pg.abc&port=5433",
       "postgresql://objdb@/objdb?host=/tmp/objdb-pg.abc&port=5433"},
      {"postgresql://db.example.org:5432/objdb", "postgresql://db.example.org:5432/objdb"},
  };
  for (const auto& [uri, redacted] : cases) {
    EXPECT_EQ(redactPostgresUri(uri), redacted) << uri;
    EXPECT_THAT(redactPostgresUri(uri), Not(HasSubstr("secret"))) << uri;
  }
  EXPECT_TRUE(isPostgresTarget("postgresql://objdb@/objdb?host=/tmp/x"));
  EXPECT_TRUE(isPostgresTarget("postgres://db.example.org/objdb"));
  EXPECT_FALSE(isPostgresTarget("/var/lib/objdb/objdb.sqlite"));
  EXPECT_FALSE(isPostgresTarget("postgresql.sqlite"));
  EXPECT_FALSE(isPostgresTarget(""));
}

TEST(PostgresStore, AFlippedBlobByteFailsThatRowOnly) {
  const std::string uri = freshDatabase("pg_flipped_byte");
  ASSERT_FALSE(uri.empty());
  auto store = openStore(uri);
  ASSERT_NE(store, nullptr);
  model::ObjectModel intact = makeStoreModel(1, 2);
  intact.id = store->addModel(model::cloneModel(intact)).value();
  model::ObjectModel damaged = makeStoreModel(2, 2);
  damaged.id = store->addModel(model::cloneModel(damaged)).value();
  ASSERT_TRUE(store->check().value().ok());

  // The cloud's last byte is payload (after the 32-byte header): its checksum no longer holds.
  RawSql sql(uri);
  ASSERT_EQ(sql.run(absl::StrFormat(
                "UPDATE models SET cloud = set_byte(cloud, length(cloud) - 1, "
                "get_byte(cloud, length(cloud) - 1) # 1) WHERE id = %d AND length(cloud) > %d",
                damaged.id, kBlobHeaderBytes)),
            "1");

  const auto broken = store->model(damaged.id);
  ASSERT_FALSE(broken.ok());
  EXPECT_EQ(broken.status().code(), absl::StatusCode::kDataLoss) << broken.status();
  EXPECT_THAT(broken.status().message(),
              HasSubstr(absl::StrFormat("models row %d, column cloud", damaged.id)));
  EXPECT_THAT(broken.status().message(), HasSubstr("checksum mismatch"));
  const auto other = store->model(intact.id);
  ASSERT_TRUE(other.ok()) << other.status();
  EXPECT_EQ(diffModels(**other, intact), "");
  EXPECT_EQ(store->modelIds().value().size(), 2u);

  const auto report = store->check();
  ASSERT_TRUE(report.ok()) << report.status();
  EXPECT_THAT(report->engine_findings, IsEmpty());
  ASSERT_EQ(report->damaged.size(), 1u);
  EXPECT_EQ(report->damaged[0].table, "models");
  EXPECT_EQ(report->damaged[0].row, damaged.id);
  EXPECT_EQ(report->damaged[0].column, "cloud");
  EXPECT_THAT(report->damaged[0].problem, HasSubstr("checksum mismatch"));
  EXPECT_GT(report->blobs_checked, 10u);
}

TEST(PostgresStore, TwoStoresOnOneDatabaseSeeEachOthersWrites) {
  const std::string uri = freshDatabase("pg_two_stores");
  ASSERT_FALSE(uri.empty());
  auto a = openStore(uri);
  auto b = openStore(uri);
  ASSERT_NE(a, nullptr);
  ASSERT_NE(b, nullptr);

  model::ObjectModel m = makeStoreModel(4, 2);
  m.id = a->addModel(model::cloneModel(m)).value();
  EXPECT_EQ(b->modelIds().value(), std::vector<int64_t>{m.id});
  const auto seen = b->model(m.id);
  ASSERT_TRUE(seen.ok()) << seen.status();
  EXPECT_EQ(diffModels(**seen, m), "");

  const database::RawSegmentRecord segment = makeRawSegment("tuesday", 9, 5);
  ASSERT_TRUE(b->putRawSegment(segment).ok());
  const auto loaded = a->rawSegment(segment.key);
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  EXPECT_EQ((*loaded)->key, segment.key);
  EXPECT_TRUE((*loaded)->T_world_segment.matrix() == segment.T_world_segment.matrix());
  EXPECT_EQ(diffLayers(*(*loaded)->grid, *segment.grid), "");
  EXPECT_EQ((*loaded)->voxels, segment.voxels);
  EXPECT_EQ((*loaded)->extraction_frame, segment.extraction_frame);
  EXPECT_EQ(a->rawSegmentId(segment.key).value(), b->rawSegmentId(segment.key).value());

  // A removal by one is seen by the other.
  ASSERT_TRUE(a->removeModel(m.id).ok());
  EXPECT_EQ(b->model(m.id).status().code(), absl::StatusCode::kNotFound);
  EXPECT_TRUE(b->modelIds().value().empty());
}

// Two servers' worth of writers on one database: SERIALIZABLE conflicts are retried, identity
// ids never collide, nothing is lost.
TEST(PostgresStore, ConcurrentWritersOnTwoStoresAllLand) {
  const std::string uri = freshDatabase("pg_writers");
  ASSERT_FALSE(uri.empty());
  auto a = openStore(uri);
  auto b = openStore(uri);
  ASSERT_NE(a, nullptr);
  ASSERT_NE(b, nullptr);
  constexpr int kStores = 2, kThreadsPerStore = 4, kModelsPerThread = 10;
  constexpr size_t kModels = kStores * kThreadsPerStore * kModelsPerThread;
  PostgresStore* stores[kStores] = {a.get(), b.get()};
  struct Written {
    int64_t id;
    uint32_t seed;  // of the replacement, the model's last version
    int observations;
  };
  std::mutex mutex;
  std::vector<Written> written;
  std::vector<std::string> errors;
  std::latch start(kStores * kThreadsPerStore);
  std::vector<std::thread> threads;
  for (int s = 0; s < kStores; ++s) {
    for (int t = 0; t < kThreadsPerStore; ++t) {
      threads.emplace_back([&, s, t] {
        PostgresStore& store = *stores[s];
        auto fail = [&](const std::string& what, const Status& status) {
          std::lock_guard lock(mutex);
          errors.push_back(absl::StrFormat("store %d thread %d, %s: %s", s, t, what,
                                           status.ToString()));
        };
        start.arrive_and_wait();
        for (int i = 0; i < kModelsPerThread; ++i) {
          const uint32_t seed = uint32_t(1000 * (s + 1) + 100 * t + i);
          const int observations = 1 + i % 3;
          const auto id = store.addModel(makeStoreModel(seed, observations));
          if (!id.ok()) {
            fail("adding a model", id.status());
            continue;
          }
          model::ObjectModel replacement = makeStoreModel(seed + 50000, observations);
          replacement.id = *id;
          const Status replaced = store.replaceModel(std::move(replacement), std::nullopt);
          if (!replaced.ok()) {
            fail(absl::StrFormat("replacing model %d", *id), replaced);
            continue;
          }
          SessionInfo session;
          session.name = absl::StrFormat("writer_%d_%d_%d", s, t, i);
          const auto begun = store.beginSession(session);
          if (!begun.ok()) fail("beginning session " + session.name, begun.status());
          std::lock_guard lock(mutex);
          written.push_back({*id, seed + 50000, observations});
        }
      });
    }
  }
  for (auto& thread : threads) thread.join();
  std::cout << "transaction retries: store A " << a->transactionRetries() << ", store B "
            << b->transactionRetries() << "\n";
  EXPECT_THAT(errors, IsEmpty());
  ASSERT_EQ(written.size(), kModels);

  std::set<int64_t> ids;
  for (const Written& w : written) ids.insert(w.id);
  EXPECT_EQ(ids.size(), kModels) << "an id was handed out twice";
  for (const Written& w : written) {
    const auto loaded = (w.id % 2 ? a : b)->model(w.id);
    ASSERT_TRUE(loaded.ok()) << loaded.status();
    model::ObjectModel expected = makeStoreModel(w.seed, w.observations);
    expected.id = w.id;
    EXPECT_EQ(diffModels(**loaded, expected), "") << "model " << w.id;
  }
  EXPECT_EQ(b->modelIds().value(), std::vector<int64_t>(ids.begin(), ids.end()));
  EXPECT_EQ(a->stats().value().active_models, int64_t(kModels));
  size_t writer_sessions = 0;
  const std::vector<SessionInfo> listed = b->sessions().value();
  for (const SessionInfo& s : listed) {
    writer_sessions += s.name.rfind("writer_", 0) == 0 ? 1 : 0;
  }
  EXPECT_EQ(writer_sessions, kModels);
}

TEST(PostgresStore, BackupIsAPgDumpArchiveThatRestores) {
  const std::string bin = postgresClientDir();
  ASSERT_FALSE(bin.empty()) << "pg_dump and pg_restore are neither in /usr/lib/postgresql/*/bin "
                               "nor on PATH: install the Debian package postgresql";
  // backupTo runs the pg_dump it finds on PATH: this one.
  const char* path = std::getenv("PATH");
  ASSERT_EQ(::setenv("PATH", (bin + ":" + (path == nullptr ? "" : path)).c_str(), 1), 0);

  const std::string uri = freshDatabase("pg_backup");
  const std::string restore_uri = freshDatabase("pg_restored");
  ASSERT_FALSE(uri.empty());
  ASSERT_FALSE(restore_uri.empty());
  auto store = openStore(uri);
  ASSERT_NE(store, nullptr);
  std::vector<model::ObjectModel> originals;
  for (uint32_t seed = 1; seed <= 3; ++seed) {
    model::ObjectModel m = makeStoreModel(seed, int(seed));
    m.id = store->addModel(model::cloneModel(m)).value();
    originals.push_back(std::move(m));
  }
  const auto scene = std::make_shared<const tsdf::TsdfLayer>(originals[0].grid.clone());
  ASSERT_TRUE(store->putScene("s0", scene).ok());

  TempDir dir;
  const std::string archive = (dir / "db.dump").string();
  const auto report = store->backupTo(archive);
  ASSERT_TRUE(report.ok()) << report.status();
  EXPECT_GT(report->bytes, 0);
  ASSERT_TRUE(std::filesystem::exists(archive));
  EXPECT_EQ(int64_t(std::filesystem::file_size(archive)), report->bytes);
  EXPECT_EQ(std::distance(std::filesystem::directory_iterator(dir.path()),
                          std::filesystem::directory_iterator()),
            1)
      << "a partial file or pg_dump's stderr was left behind";

  const auto again = store->backupTo(archive);
  EXPECT_EQ(again.status().code(), absl::StatusCode::kAlreadyExists) << again.status();
  EXPECT_EQ(int64_t(std::filesystem::file_size(archive)), report->bytes);

  const auto [exit_code, output] =
      runShell(absl::StrCat(shellQuote(bin + "/pg_restore"), " --no-owner --exit-on-error ",
                            "--dbname=", shellQuote(restore_uri), " ", shellQuote(archive)));
  ASSERT_EQ(exit_code, 0) << "pg_restore: " << output;
  auto restored = openStore(restore_uri);
  ASSERT_NE(restored, nullptr);
  EXPECT_EQ(restored->schemaVersion(), latestSchemaVersion());
  EXPECT_EQ(restored->modelIds().value(), store->modelIds().value());
  for (const model::ObjectModel& m : originals) {
    const auto loaded = restored->model(m.id);
    ASSERT_TRUE(loaded.ok()) << loaded.status();
    EXPECT_EQ(diffModels(**loaded, m), "") << "model " << m.id;
  }
  const auto restored_scene = restored->scene("s0");
  ASSERT_TRUE(restored_scene.ok()) << restored_scene.status();
  ASSERT_NE(*restored_scene, nullptr);
  EXPECT_EQ(diffLayers(**restored_scene, *scene), "");
  // The identity sequences came along: a new model gets a new id.
  const auto next = restored->addModel(makeStoreModel(9, 1));
  ASSERT_TRUE(next.ok()) << next.status();
  EXPECT_GT(*next, originals.back().id);
}

TEST(PostgresStore, BadOptionsAreRefused) {
  const std::string uri = freshDatabase("pg_bad_options");
  ASSERT_FALSE(uri.empty());
  EXPECT_TRUE(PostgresStoreOptions().validate().ok());
  PostgresStoreOptions no_pool;
  no_pool.pool_size = 0;
  const Status invalid = no_pool.validate();
  EXPECT_EQ(invalid.code(), absl::StatusCode::kInvalidArgument) << invalid;
  EXPECT_THAT(invalid.message(), HasSubstr("pool_size must be in [1, 256], got 0"));
  const auto opened = PostgresStore::open(uri, no_pool);
  ASSERT_FALSE(opened.ok());
  EXPECT_EQ(opened.status().code(), absl::StatusCode::kInvalidArgument) << opened.status();
  EXPECT_THAT(opened.status().message(), HasSubstr("pool_size"));
  RawSql sql(uri);
  EXPECT_EQ(sql.tableCount(), "0") << "nothing is written with bad options";

  // Every other field names itself.
  PostgresStoreOptions no_timeout;
  no_timeout.connect_timeout_s = 0;
  EXPECT_THAT(no_timeout.validate().message(), HasSubstr("connect_timeout_s"));
  PostgresStoreOptions negative_retries;
  negative_retries.max_transaction_retries = -1;
  EXPECT_THAT(negative_retries.validate().message(), HasSubstr("max_transaction_retries"));
  PostgresStoreOptions no_cache;
  no_cache.max_cached_scenes = 0;
  EXPECT_THAT(no_cache.validate().message(), HasSubstr("max_cached_scenes"));
  for (const PostgresStoreOptions* bad : {&no_timeout, &negative_retries, &no_cache}) {
    EXPECT_EQ(bad->validate().code(), absl::StatusCode::kInvalidArgument);
  }
}

}  // namespace
}  // namespace objdb::storage
