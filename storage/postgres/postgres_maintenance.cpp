// PostgresStore's upkeep: the full check (observations whose raw segment row is gone, every blob
// decoded), statistics, the size on disk, and the backup (pg_dump, run as a child process).
#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <random>
#include <utility>
#include <vector>

#include "absl/strings/str_format.h"
#include "storage/backup_files.h"
#include "storage/postgres/postgres_internal.h"

extern char** environ;

namespace objdb::storage {

using pg::Params;
using pg::Result;

StatusOr<CheckReport> PostgresStore::check() const {
  CheckReport report;
  OBJDB_RETURN_IF_ERROR(impl_->read("checking the database", [&](const pg::Connection& c)
                                                                  -> Status {
    report = CheckReport();
    // Constraints are PostgreSQL's to enforce; what they cannot see: an observation whose raw
    // segment row was replaced (raw_segment_id then no longer names its session and label).
    OBJDB_ASSIGN_OR_RETURN(
        Result stale,
        c.exec("SELECT o.id, o.model_id FROM observations o JOIN raw_segments r ON "
               "r.id = o.raw_segment_id WHERE r.session_id <> o.session_id OR r.label <> o.label "
               "ORDER BY o.id",
               "checking observations"));
    for (int row = 0; row < stale.rows(); ++row) {
      report.engine_findings.push_back(absl::StrFormat(
          "observations row %d (model %d) names a raw segment of another session or label",
          stale.integer(row, 0), stale.integer(row, 1)));
    }
    for (const BlobColumn& column : checkedBlobColumns()) {
      OBJDB_ASSIGN_OR_RETURN(
          Result r, c.exec(absl::StrFormat("SELECT id, %s FROM %s WHERE %s IS NOT NULL ORDER BY id",
                                           column.column, column.table, column.column),
                           absl::StrFormat("checking %s.%s", column.table, column.column)));
      for (int row = 0; row < r.rows(); ++row) {
        ++report.blobs_checked;
        const Status status = column.decode(r.bytes(row, 1));
        if (!status.ok()) {
          report.damaged.push_back(
              {column.table, r.integer(row, 0), column.column, std::string(status.message())});
        }
      }
    }
    {
      // What no single column shows: every recorded voxel part is one of the segment's parts.
      OBJDB_ASSIGN_OR_RETURN(Result r, c.exec(kRawSegmentPartsQuery, "checking raw segment parts"));
      for (int row = 0; row < r.rows(); ++row) {
        if (auto offence = rawSegmentPartsOffence(r.text(row, 1), r.bytes(row, 2), r.bytes(row, 3))) {
          report.damaged.push_back(
              {"raw_segments", r.integer(row, 0), offence->column, std::move(offence->message)});
        }
      }
    }
    for (const MapTables* tables : {&kSceneTables, &kSavedTables}) {
      OBJDB_ASSIGN_OR_RETURN(
          Result r, c.exec(absl::StrFormat("SELECT b.id, m.voxels_per_side, b.tsdf FROM %s b "
                                           "JOIN %s m ON m.session_id = b.session_id ORDER BY b.id",
                                           tables->blocks, tables->maps),
                           absl::StrFormat("checking %s", tables->blocks)));
      for (int row = 0; row < r.rows(); ++row) {
        ++report.blobs_checked;
        const Status status = checkTsdfBlock(r.bytes(row, 2), r.integer(row, 1));
        if (!status.ok()) {
          report.damaged.push_back(
              {tables->blocks, r.integer(row, 0), "tsdf", std::string(status.message())});
        }
      }
    }
    return absl::OkStatus();
  }));
  return report;
}

StatusOr<StoreStats> PostgresStore::stats() const {
  StoreStats stats;
  OBJDB_RETURN_IF_ERROR(impl_->read("reading statistics", [&](const pg::Connection& c) -> Status {
    stats = StoreStats();
    stats.schema_version = schema_version_;
    OBJDB_ASSIGN_OR_RETURN(Result size, c.exec("SELECT pg_database_size(current_database())",
                                               "measuring the database"));
    stats.file_bytes = size.integer(0, 0);

    for (const auto& [table, bytes] : statsTables()) {
      OBJDB_ASSIGN_OR_RETURN(
          Result r, c.exec(absl::StrFormat("SELECT COUNT(*), COALESCE(SUM(%s), 0)::bigint FROM %s",
                                           bytes, table),
                           absl::StrFormat("counting %s", table)));
      stats.tables.push_back({table, r.integer(0, 0), r.integer(0, 1)});
    }
    OBJDB_ASSIGN_OR_RETURN(Result states,
                           c.exec("SELECT state, COUNT(*) FROM models GROUP BY state",
                                  "counting models"));
    for (int row = 0; row < states.rows(); ++row) {
      const std::string state = states.text(row, 0);
      const int64_t n = states.integer(row, 1);
      if (state == "active") stats.active_models = n;
      if (state == "removed") stats.removed_models = n;
      if (state == "merged") stats.merged_models = n;
    }
    return absl::OkStatus();
  }));
  return stats;
}

Status PostgresStore::checkpoint() { return absl::OkStatus(); }

namespace {

// The environment of a libpq client (pg_dump) connecting where `uri` points: this process's
// environment with every connection parameter the URI sets as its PG* variable, so that no
// password shows in the child's command line.
StatusOr<std::vector<std::string>> clientEnvironment(const std::string& uri,
                                                     int connect_timeout_s) {
  char* error = nullptr;
  PQconninfoOption* options = PQconninfoParse(uri.c_str(), &error);
  if (options == nullptr) {
    const std::string why = error ? error : "malformed";
    PQfreemem(error);
    return absl::InvalidArgumentError(absl::StrFormat("backup: the database URI: %s", why));
  }
  std::vector<std::string> env;
  std::vector<std::string> names;
  bool has_timeout = false;
  for (const PQconninfoOption* o = options; o->keyword != nullptr; ++o) {
    if (o->val == nullptr || o->envvar == nullptr) continue;
    has_timeout = has_timeout || std::string_view(o->envvar) == "PGCONNECT_TIMEOUT";
    env.push_back(absl::StrFormat("%s=%s", o->envvar, o->val));
    names.push_back(std::string(o->envvar) + "=");
  }
  PQconninfoFree(options);
  if (!has_timeout && std::getenv("PGCONNECT_TIMEOUT") == nullptr) {
    env.push_back(absl::StrFormat("PGCONNECT_TIMEOUT=%d", connect_timeout_s));
  }
  for (char** e = environ; *e != nullptr; ++e) {
    const std::string_view entry(*e);
    bool overridden = false;
    for (const auto& name : names) overridden = overridden || entry.substr(0, name.size()) == name;
    if (!overridden) env.emplace_back(entry);
  }
  return env;
}

// Runs `argv` with `env`, waits for it; its stderr goes to `stderr_path`.
StatusOr<int> runChild(const std::vector<std::string>& argv, const std::vector<std::string>& env,
                       const std::string& stderr_path) {
  std::vector<char*> args, envp;
  for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  for (const auto& e : env) envp.push_back(const_cast<char*>(e.c_str()));
  envp.push_back(nullptr);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, STDIN_FILENO, "/dev/null", O_RDONLY, 0);
  posix_spawn_file_actions_addopen(&actions, STDERR_FILENO, stderr_path.c_str(),
                                   O_WRONLY | O_CREAT | O_TRUNC, 0600);
  pid_t pid = 0;
  const int spawned = posix_spawnp(&pid, args[0], &actions, nullptr, args.data(), envp.data());
  posix_spawn_file_actions_destroy(&actions);
  if (spawned != 0) {
    if (spawned == ENOENT) {
      return absl::FailedPreconditionError(absl::StrFormat(
          "backup: %s is not installed (Debian: postgresql-client); PostgreSQL databases are "
          "backed up with pg_dump",
          argv[0]));
    }
    return absl::UnavailableError(
        absl::StrFormat("backup: starting %s: %s", argv[0], std::strerror(spawned)));
  }
  int wstatus = 0;
  while (::waitpid(pid, &wstatus, 0) < 0) {
    if (errno != EINTR) {
      return absl::InternalError(absl::StrFormat("backup: waiting for %s: %s", argv[0],
                                                 std::strerror(errno)));
    }
  }
  return WIFEXITED(wstatus) ? WEXITSTATUS(wstatus) : 128 + WTERMSIG(wstatus);
}

std::string firstLines(const std::string& path, size_t max_bytes) {
  std::string out(max_bytes, '\0');
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return "";
  const ssize_t n = ::read(fd, out.data(), out.size());
  ::close(fd);
  out.resize(n > 0 ? size_t(n) : 0);
  while (!out.empty() && (out.back() == '\n' || out.back() == ' ')) out.pop_back();
  return out;
}

}  // namespace

StatusOr<BackupReport> PostgresStore::backupTo(const std::string& path) const {
  std::error_code ec;
  if (std::filesystem::exists(path, ec)) {
    return absl::AlreadyExistsError(
        absl::StrFormat("backup: %s exists; choose a new file (nothing was written)", path));
  }
  OBJDB_ASSIGN_OR_RETURN(const std::vector<std::string> env, clientEnvironment(uri_, options_.connect_timeout_s));
  std::random_device random;
  const std::string partial = absl::StrFormat("%s.partial-%08x", path, random());
  const std::string errors = partial + ".stderr";
  // One consistent snapshot of the database while writers go on (pg_dump's own transaction),
  // in pg_dump's custom format: pg_restore --dbname=... restores it into an empty database.
  auto rc = runChild({"pg_dump", "--format=custom", "--no-owner", "--file=" + partial}, env,
                     errors);
  const std::string why = firstLines(errors, 2000);
  std::filesystem::remove(errors, ec);
  if (!rc.ok()) {
    std::filesystem::remove(partial, ec);
    return rc.status();
  }
  if (*rc != 0) {
    std::filesystem::remove(partial, ec);
    return absl::UnavailableError(
        absl::StrFormat("backup: pg_dump of %s failed (exit %d): %s", describe(), *rc, why));
  }
  // Durable before it gets its name; link() never replaces a file that appeared meanwhile.
  syncPath(partial);
  BackupReport report;
  report.bytes = int64_t(std::filesystem::file_size(partial, ec));
  const int named = ::link(partial.c_str(), path.c_str());
  const int link_errno = errno;
  std::filesystem::remove(partial, ec);
  if (named != 0) return backupNamingError(path, link_errno);
  syncDirectoryOf(path);
  return report;
}

}  // namespace objdb::storage
