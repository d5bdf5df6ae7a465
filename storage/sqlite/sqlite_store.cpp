#include "storage/sqlite/sqlite_store.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <optional>

#include "absl/strings/numbers.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_split.h"
#include "core/common/logging.h"
#include "storage/row_codec.h"
#include "storage/sqlite/sqlite_store_internal.h"

namespace objdb::storage {

using internal::kNow;

Status SqliteStoreOptions::validate() const {
  if (synchronous != "FULL" && synchronous != "NORMAL") {
    return absl::InvalidArgumentError(
        absl::StrFormat("storage.synchronous must be FULL or NORMAL, got '%s'", synchronous));
  }
  OBJDB_RETURN_IF_ERROR(checkOptionRange("busy_timeout_ms", busy_timeout_ms, 0, 600000));
  OBJDB_RETURN_IF_ERROR(checkOptionRange("max_cached_scenes", max_cached_scenes, 1, 1024));
  OBJDB_RETURN_IF_ERROR(checkOptionRange("max_readers", max_readers, 1, 256));
  if (!(journal_size_limit_bytes >= 0)) {
    return absl::InvalidArgumentError("storage.journal_size_limit_bytes must be >= 0");
  }
  return absl::OkStatus();
}

SqliteStore::SqliteStore(std::string path, SqliteStoreOptions options)
    : path_(std::move(path)),
      options_(std::move(options)),
      scene_cache_(size_t(options_.max_cached_scenes)) {}

SqliteStore::~SqliteStore() = default;

std::string SqliteStore::describe() const { return path_; }

StatusOr<std::unique_ptr<SqliteStore>> SqliteStore::open(const std::string& path,
                                                         const SqliteStoreOptions& options) {
  return open(path, options, schemaMigrations());
}

StatusOr<std::unique_ptr<SqliteStore>> SqliteStore::open(const std::string& path,
                                                         const SqliteStoreOptions& options,
                                                         const std::vector<Migration>& migrations) {
  OBJDB_RETURN_IF_ERROR(options.validate());
  std::error_code ec;
  const bool exists = std::filesystem::exists(path, ec);
  if (!exists && (options.read_only || !options.create_if_missing)) {
    return absl::NotFoundError(absl::StrFormat("no database at %s", path));
  }
  if (exists && !std::filesystem::is_regular_file(path, ec)) {
    return absl::FailedPreconditionError(absl::StrFormat("%s is not a regular file", path));
  }
  std::unique_ptr<SqliteStore> store(new SqliteStore(path, options));
  if (!exists) {
    // Created here (empty: SQLite sets it up as a new database) so that the store can register
    // the file before any connection opens it.
    const int fd = ::open(path.c_str(), O_CREAT | O_EXCL | O_WRONLY | O_CLOEXEC, 0644);
    if (fd < 0) {
      return absl::UnavailableError(
          absl::StrFormat("creating %s: %s", path, std::strerror(errno)));
    }
    ::close(fd);  // a new file: no connection of this process has it open
  }
  // One writer per file: the server and `objdb ingest` each keep an in-memory copy of what the
  // database holds (the matcher's index), which a second writer would silently invalidate.
  OBJDB_ASSIGN_OR_RETURN(FileRegistration registration,
                         FileRegistration::acquire(path, !options.read_only));
  store->registration_.emplace(std::move(registration));
  ConnectionOptions co;
  co.read_only = options.read_only;
  co.create = !exists;
  co.busy_timeout_ms = options.busy_timeout_ms;
  co.synchronous = options.synchronous;
  OBJDB_ASSIGN_OR_RETURN(Connection connection, Connection::open(path, co));
  if (options.quick_check_on_open && exists) {
    OBJDB_ASSIGN_OR_RETURN(Statement check, Statement::prepare(connection, "PRAGMA quick_check"));
    auto row = check.step();
    if (!row.ok()) return annotate(row.status(), absl::StrFormat("%s failed its check", path));
    const std::string first = *row ? check.columnText(0) : std::string("no result");
    if (first != "ok") {
      return absl::DataLossError(absl::StrFormat("%s is corrupt: %s", path, first));
    }
  }
  OBJDB_ASSIGN_OR_RETURN(store->schema_,
                         prepareSchema(connection, path, migrations, options.read_only));
  if (!options.read_only) {
    OBJDB_RETURN_IF_ERROR(connection.exec(
        absl::StrFormat("PRAGMA journal_size_limit=%d", options.journal_size_limit_bytes),
        "setting journal_size_limit"));
    store->writer_.emplace(std::move(connection));
  } else {
    store->idle_readers_.push_back(std::move(connection));
  }
  logger("storage")->info("opened {} (schema {}{})", path, store->schema_.version_after,
                          store->schema_.created ? ", new" : "");
  return store;
}

StatusOr<SqliteStore::ReaderLease> SqliteStore::reader() const {
  {
    std::lock_guard lock(reader_mutex_);
    if (!idle_readers_.empty()) {
      Connection c = std::move(idle_readers_.back());
      idle_readers_.pop_back();
      return ReaderLease(this, std::move(c));
    }
  }
  ConnectionOptions co;
  co.read_only = true;
  co.busy_timeout_ms = options_.busy_timeout_ms;
  co.synchronous = options_.synchronous;
  OBJDB_ASSIGN_OR_RETURN(Connection c, Connection::open(path_, co));
  return ReaderLease(this, std::move(c));
}

StatusOr<std::unique_lock<std::mutex>> SqliteStore::holdWriter() const {
  std::unique_lock lock(write_mutex_);
  if (!writer_) {
    return absl::FailedPreconditionError(absl::StrFormat("%s is open read-only", path_));
  }
  return lock;
}

Status SqliteStore::putRawSegment(const database::RawSegmentRecord& segment) {
  OBJDB_ASSIGN_OR_RETURN(const EncodedRawSegment e, encodeRawSegment(segment, options_.blobs));
  OBJDB_ASSIGN_OR_RETURN(const std::unique_lock<std::mutex> held, holdWriter());
  const std::string context =
      absl::StrFormat("storing raw segment %s/%d", segment.key.session, segment.key.label);
  auto body = [&]() -> Status {
    OBJDB_ASSIGN_OR_RETURN(Transaction txn,
                           Transaction::begin(*writer_, Transaction::Kind::kWrite));
    OBJDB_ASSIGN_OR_RETURN(const int64_t sid, sessionIdForWrite(segment.key.session));
    OBJDB_ASSIGN_OR_RETURN(
        Statement s,
        Statement::prepare(
            *writer_,
            "INSERT INTO raw_segments(session_id, label, pose, grid, voxels, "
            "extraction_frame, observation_depth_m, parts, voxel_parts, extracted_at) "
            "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, %s) "
            "ON CONFLICT(session_id, label) DO UPDATE SET pose = excluded.pose, "
            "grid = excluded.grid, voxels = excluded.voxels, "
            "extraction_frame = excluded.extraction_frame, "
            "observation_depth_m = excluded.observation_depth_m, parts = excluded.parts, "
            "voxel_parts = excluded.voxel_parts, extracted_at = excluded.extracted_at",
            kNow));
    s.bind(1, sid).bind(2, int64_t(segment.key.label)).bindBlob(3, e.pose).bindBlob(4, e.grid);
    s.bindBlob(5, e.voxels).bind(6, segment.extraction_frame);
    s.bind(7, double(segment.observation_depth_m)).bind(8, e.parts);
    if (e.voxel_parts) {
      s.bindBlob(9, *e.voxel_parts);
    } else {
      s.bindNull(9);
    }
    OBJDB_RETURN_IF_ERROR(s.run());
    return txn.commit();
  };
  return annotate(body(), context);
}

StatusOr<std::shared_ptr<const database::RawSegmentRecord>> SqliteStore::rawSegment(
    const database::SegmentKey& key) const {
  OBJDB_ASSIGN_OR_RETURN(ReaderLease lease, reader());
  OBJDB_ASSIGN_OR_RETURN(Statement s,
                         Statement::prepare(*lease,
                                            "SELECT %s FROM raw_segments r JOIN sessions s "
                                            "ON s.id = r.session_id WHERE s.name = ? AND "
                                            "r.label = ?",
                                            kRawSegmentColumns));
  s.bind(1, key.session).bind(2, int64_t(key.label));
  OBJDB_ASSIGN_OR_RETURN(const bool row, s.step());
  if (!row) {
    return absl::NotFoundError(absl::StrFormat("no raw segment %s/%d", key.session, key.label));
  }
  return decodeRawSegment(key, readRawSegmentColumns(internal::StatementRow(s)));
}

StatusOr<std::vector<float>> SqliteStore::observationDepths(
    const std::vector<database::SegmentKey>& keys) const {
  OBJDB_ASSIGN_OR_RETURN(ReaderLease lease, reader());
  OBJDB_ASSIGN_OR_RETURN(Statement s,
                         Statement::prepare(*lease,
                                            "SELECT r.observation_depth_m FROM raw_segments r "
                                            "JOIN sessions s ON s.id = r.session_id WHERE "
                                            "s.name = ? AND r.label = ?"));
  std::vector<float> depths;
  depths.reserve(keys.size());
  for (const auto& key : keys) {
    OBJDB_RETURN_IF_ERROR(s.reset());
    s.bind(1, key.session).bind(2, int64_t(key.label));
    OBJDB_ASSIGN_OR_RETURN(const bool row, s.step());
    if (!row) {
      return absl::NotFoundError(absl::StrFormat("no raw segment %s/%d", key.session, key.label));
    }
    depths.push_back(float(s.columnDouble(0)));
  }
  return depths;
}

StatusOr<int64_t> SqliteStore::rawSegmentId(const database::SegmentKey& key) const {
  OBJDB_ASSIGN_OR_RETURN(ReaderLease lease, reader());
  OBJDB_ASSIGN_OR_RETURN(Statement s,
                         Statement::prepare(*lease,
                                            "SELECT r.id FROM raw_segments r JOIN sessions s ON "
                                            "s.id = r.session_id WHERE s.name = ? AND r.label = ?"));
  s.bind(1, key.session).bind(2, int64_t(key.label));
  OBJDB_ASSIGN_OR_RETURN(const bool row, s.step());
  if (!row) {
    return absl::NotFoundError(absl::StrFormat("no raw segment %s/%d", key.session, key.label));
  }
  return s.columnInt(0);
}

StatusOr<std::vector<database::SegmentKey>> SqliteStore::rawSegmentKeys() const {
  OBJDB_ASSIGN_OR_RETURN(ReaderLease lease, reader());
  OBJDB_ASSIGN_OR_RETURN(Statement s,
                         Statement::prepare(*lease,
                                            "SELECT s.name, r.label FROM raw_segments r JOIN "
                                            "sessions s ON s.id = r.session_id ORDER BY r.id"));
  std::vector<database::SegmentKey> keys;
  while (true) {
    OBJDB_ASSIGN_OR_RETURN(const bool row, s.step());
    if (!row) break;
    keys.push_back({s.columnText(0), uint32_t(s.columnInt(1))});
  }
  return keys;
}

StatusOr<std::vector<database::MergeRecord>> SqliteStore::mergeRecords() const {
  return readMergeRecords(std::nullopt);
}

StatusOr<std::vector<database::MergeRecord>> SqliteStore::mergeRecordsInto(int64_t target) const {
  return readMergeRecords(target);
}

StatusOr<std::vector<database::MergeRecord>> SqliteStore::readMergeRecords(
    std::optional<int64_t> target) const {
  OBJDB_ASSIGN_OR_RETURN(ReaderLease lease, reader());
  OBJDB_ASSIGN_OR_RETURN(Statement s,
                         Statement::prepare(*lease, "SELECT %s FROM merge_records %s ORDER BY id",
                                            kMergeRecordColumns, target ? "WHERE target = ?" : ""));
  if (target) s.bind(1, *target);
  std::vector<database::MergeRecord> records;
  while (true) {
    OBJDB_ASSIGN_OR_RETURN(const bool row, s.step());
    if (!row) break;
    OBJDB_ASSIGN_OR_RETURN(database::MergeRecord r, readMergeRecord(internal::StatementRow(s)));
    records.push_back(std::move(r));
  }
  return records;
}

}  // namespace objdb::storage
