// SqliteStore's upkeep: the full check (SQLite's integrity and foreign key checks, every blob
// decoded), statistics, the WAL checkpoint, the size on disk and the online backup.
#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <functional>
#include <optional>
#include <random>

#include "absl/strings/str_format.h"
#include "storage/backup_files.h"
#include "storage/row_codec.h"
#include "storage/sqlite/sqlite_store.h"
#include "storage/sqlite/sqlite_store_internal.h"

namespace objdb::storage {

StatusOr<CheckReport> SqliteStore::check() const {
  OBJDB_ASSIGN_OR_RETURN(ReaderLease lease, reader());
  OBJDB_ASSIGN_OR_RETURN(Transaction snapshot, Transaction::begin(*lease, Transaction::Kind::kRead));
  CheckReport report;
  {
    OBJDB_ASSIGN_OR_RETURN(Statement s, Statement::prepare(*lease, "PRAGMA integrity_check"));
    while (true) {
      OBJDB_ASSIGN_OR_RETURN(const bool row, s.step());
      if (!row) break;
      const std::string line = s.columnText(0);
      if (line != "ok") report.engine_findings.push_back(line);
    }
    OBJDB_ASSIGN_OR_RETURN(Statement fk, Statement::prepare(*lease, "PRAGMA foreign_key_check"));
    while (true) {
      OBJDB_ASSIGN_OR_RETURN(const bool row, fk.step());
      if (!row) break;
      report.engine_findings.push_back(absl::StrFormat(
          "foreign key: %s row %d refers to a missing %s row", fk.columnText(0), fk.columnInt(1),
          fk.columnText(2)));
    }
  }
  for (const BlobColumn& c : checkedBlobColumns()) {
    OBJDB_ASSIGN_OR_RETURN(Statement s,
                           Statement::prepare(*lease,
                                              "SELECT rowid, %s FROM %s WHERE %s IS NOT NULL "
                                              "ORDER BY rowid",
                                              c.column, c.table, c.column));
    while (true) {
      OBJDB_ASSIGN_OR_RETURN(const bool row, s.step());
      if (!row) break;
      ++report.blobs_checked;
      const Status status = c.decode(s.columnBlob(1));
      if (!status.ok()) {
        report.damaged.push_back({c.table, s.columnInt(0), c.column, std::string(status.message())});
      }
    }
  }
  {
    // What no single column shows: every recorded voxel part is one of the segment's parts.
    OBJDB_ASSIGN_OR_RETURN(Statement s, Statement::prepare(*lease, kRawSegmentPartsQuery));
    while (true) {
      OBJDB_ASSIGN_OR_RETURN(const bool row, s.step());
      if (!row) break;
      if (auto offence = rawSegmentPartsOffence(s.columnText(1), s.columnBlob(2), s.columnBlob(3))) {
        report.damaged.push_back(
            {"raw_segments", s.columnInt(0), offence->column, std::move(offence->message)});
      }
    }
  }
  for (const MapTables* tables : {&kSceneTables, &kSavedTables}) {
    OBJDB_ASSIGN_OR_RETURN(Statement blocks,
                           Statement::prepare(*lease,
                                              "SELECT b.rowid, m.voxels_per_side, b.tsdf "
                                              "FROM %s b JOIN %s m ON m.session_id = "
                                              "b.session_id ORDER BY b.rowid",
                                              tables->blocks, tables->maps));
    while (true) {
      OBJDB_ASSIGN_OR_RETURN(const bool row, blocks.step());
      if (!row) break;
      ++report.blobs_checked;
      const Status status = checkTsdfBlock(blocks.columnBlob(2), blocks.columnInt(1));
      if (!status.ok()) {
        report.damaged.push_back(
            {tables->blocks, blocks.columnInt(0), "tsdf", std::string(status.message())});
      }
    }
  }
  OBJDB_RETURN_IF_ERROR(snapshot.commit());
  return report;
}

namespace {

void removeDatabaseFiles(const std::string& path) {
  std::error_code ec;
  for (const char* suffix : {"", "-wal", "-shm", "-journal"}) {
    std::filesystem::remove(path + suffix, ec);
  }
}

// A new, empty file next to `path` whose name nobody else uses (created with O_EXCL).
StatusOr<std::string> createUniqueSibling(const std::string& path) {
  std::random_device random;
  for (int attempt = 0; attempt < 16; ++attempt) {
    const std::string name = absl::StrFormat("%s.partial-%08x", path, random());
    const int fd = ::open(name.c_str(), O_CREAT | O_EXCL | O_WRONLY | O_CLOEXEC, 0644);
    if (fd >= 0) {
      ::close(fd);
      return name;
    }
    if (errno != EEXIST) {
      return absl::UnavailableError(
          absl::StrFormat("backup: creating %s: %s", name, std::strerror(errno)));
    }
  }
  return absl::UnavailableError(absl::StrFormat("backup: no free temporary name next to %s", path));
}

}  // namespace

StatusOr<BackupReport> SqliteStore::backupTo(const std::string& path) const {
  std::error_code ec;
  // A stale -wal or -journal of an earlier file of that name would be replayed over the copy.
  for (const char* suffix : {"", "-wal", "-shm", "-journal"}) {
    if (std::filesystem::exists(path + suffix, ec)) {
      return absl::AlreadyExistsError(absl::StrFormat(
          "backup: %s%s exists; choose a new file (nothing was written)", path, suffix));
    }
  }
  OBJDB_ASSIGN_OR_RETURN(ReaderLease lease, reader());
  OBJDB_ASSIGN_OR_RETURN(const std::string partial, createUniqueSibling(path));
  std::optional<Connection> dest;
  {
    ConnectionOptions dest_options;
    auto opened = Connection::open(partial, dest_options);
    if (!opened.ok()) {
      removeDatabaseFiles(partial);
      return annotate(opened.status(), "backup: creating the copy");
    }
    dest.emplace(std::move(*opened));
  }
  BackupReport report;
  auto copy = [&]() -> Status {
    sqlite3_backup* backup = sqlite3_backup_init(dest->get(), "main", (*lease).get(), "main");
    if (backup == nullptr) return sqliteStatus(sqlite3_errcode(dest->get()), dest->get(), "backup");
    // Every page in one step: one read snapshot of the source (WAL: writers go on meanwhile).
    int rc = SQLITE_OK;
    for (int attempt = 0; attempt < 20; ++attempt) {
      rc = sqlite3_backup_step(backup, -1);
      if (rc != SQLITE_BUSY && rc != SQLITE_LOCKED) break;
      sqlite3_sleep(50);
    }
    report.pages = sqlite3_backup_pagecount(backup);
    const int finished = sqlite3_backup_finish(backup);
    if (rc != SQLITE_DONE) return sqliteStatus(rc, dest->get(), "backup: copying pages");
    OBJDB_RETURN_IF_ERROR(sqliteStatus(finished, dest->get(), "backup: finishing"));
    OBJDB_ASSIGN_OR_RETURN(const int64_t page_size,
                           dest->queryInt("PRAGMA page_size", "backup: page size"));
    report.bytes = report.pages * page_size;
    // The copy is a file of its own: WAL mode (as the store sets up new files), everything in
    // the main file.
    auto mode = Statement::prepare(*dest, "PRAGMA journal_mode=WAL");
    if (!mode.ok()) return mode.status();
    OBJDB_RETURN_IF_ERROR(mode->step().status());
    return dest->exec("PRAGMA wal_checkpoint(TRUNCATE)", "backup: checkpointing the copy");
  };
  Status copied = copy();
  dest.reset();  // closes the copy (synced: synchronous=FULL)
  if (copied.ok()) {
    // link() never replaces: a file that appeared at `path` meanwhile stays as it is. Where
    // the file system has no hard links, a rename that never replaces either.
    int named = ::link(partial.c_str(), path.c_str());
    if (named != 0 && (errno == EPERM || errno == EOPNOTSUPP || errno == ENOSYS)) {
      named = ::renameat2(AT_FDCWD, partial.c_str(), AT_FDCWD, path.c_str(), RENAME_NOREPLACE);
    }
    if (named != 0) copied = backupNamingError(path, errno);
  }
  removeDatabaseFiles(partial);
  if (!copied.ok()) return copied;
  syncDirectoryOf(path);
  return report;
}

StatusOr<StoreStats> SqliteStore::stats() const {
  OBJDB_ASSIGN_OR_RETURN(ReaderLease lease, reader());
  OBJDB_ASSIGN_OR_RETURN(Transaction snapshot, Transaction::begin(*lease, Transaction::Kind::kRead));
  StoreStats stats;
  stats.schema_version = schema_.version_after;
  OBJDB_ASSIGN_OR_RETURN(const int64_t pages, (*lease).queryInt("PRAGMA page_count", "page_count"));
  OBJDB_ASSIGN_OR_RETURN(const int64_t page_size, (*lease).queryInt("PRAGMA page_size", "page_size"));
  stats.file_bytes = pages * page_size;

  for (const auto& [table, bytes] : statsTables()) {
    OBJDB_ASSIGN_OR_RETURN(
        Statement s,
        Statement::prepare(*lease, "SELECT COUNT(*), COALESCE(SUM(%s), 0) FROM %s", bytes, table));
    OBJDB_ASSIGN_OR_RETURN(const bool row, s.step());
    if (row) stats.tables.push_back({table, s.columnInt(0), s.columnInt(1)});
  }
  OBJDB_ASSIGN_OR_RETURN(
      Statement states,
      Statement::prepare(*lease, "SELECT state, COUNT(*) FROM models GROUP BY state"));
  while (true) {
    OBJDB_ASSIGN_OR_RETURN(const bool row, states.step());
    if (!row) break;
    const std::string state = states.columnText(0);
    const int64_t n = states.columnInt(1);
    if (state == "active") stats.active_models = n;
    if (state == "removed") stats.removed_models = n;
    if (state == "merged") stats.merged_models = n;
  }
  OBJDB_RETURN_IF_ERROR(snapshot.commit());
  return stats;
}

Status SqliteStore::checkpoint() {
  OBJDB_ASSIGN_OR_RETURN(const std::unique_lock<std::mutex> held, holdWriter());
  return writer_->exec("PRAGMA wal_checkpoint(TRUNCATE)", "checkpointing the WAL");
}

int64_t SqliteStore::diskBytes() const {
  int64_t total = 0;
  for (const char* suffix : {"", "-wal", "-shm"}) {
    std::error_code ec;
    const auto size = std::filesystem::file_size(path_ + suffix, ec);
    if (!ec) total += int64_t(size);
  }
  return total;
}

}  // namespace objdb::storage
