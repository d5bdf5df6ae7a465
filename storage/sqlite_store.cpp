#include "storage/sqlite_store.h"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <random>
#include <set>
#include <mutex>
#include <functional>
#include <map>
#include <optional>

#include <nlohmann/json.hpp>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_split.h"
#include "core/common/logging.h"

namespace objdb::storage {

// A model's columns, encoded outside the write lock.
struct EncodedModel {
  bool planar = false;
  bool structure = false;
  double plane_inlier_ratio = 0;
  int64_t num_points = 0, num_keypoints = 0;
  double voxel_size = 0;
  Eigen::Vector3f bbox_min = Eigen::Vector3f::Zero(), bbox_max = Eigen::Vector3f::Zero();
  std::string grid, surface_voxels, cloud, keypoints, descriptors;
  model::BuildTimings timings;
  struct Obs {
    std::string session;
    int64_t label;
    std::string T_world_object, T_object_segment;
  };
  std::vector<Obs> observations;
};

namespace {

constexpr const char* kNow = "strftime('%Y-%m-%dT%H:%M:%fZ','now')";
constexpr MapTables kSceneTables{"scene", "scene_maps", "scene_blocks", "scene_label_blocks",
                                 false};
constexpr MapTables kSavedTables{"saved map", "saved_maps", "saved_blocks", "saved_label_blocks",
                                 true};

// Blob errors keep their code (DATA_LOSS) and gain the row they sit in.
Status inRow(const Status& status, std::string_view table, int64_t row, std::string_view column) {
  return annotate(status, absl::StrFormat("%s row %d, column %s", table, row, column));
}

// raw_segments.parts: GSM labels, comma-separated ("" = none recorded: a segment stored before
// schema 4). Anything else is damage.
StatusOr<std::vector<uint32_t>> parseParts(const std::string& text) {
  std::vector<uint32_t> parts;
  if (text.empty()) return parts;
  for (const absl::string_view item : absl::StrSplit(text, ',')) {
    uint32_t label = 0;
    if (!absl::SimpleAtoi(item, &label) || label == 0) {
      return absl::DataLossError(absl::StrFormat("parts \"%s\" is not a list of GSM labels", text));
    }
    parts.push_back(label);
  }
  return parts;
}

EncodedModel encodeModel(const model::ObjectModel& m, const BlobOptions& options) {
  EncodedModel e;
  e.planar = m.planar;
  e.structure = m.structure;
  e.plane_inlier_ratio = m.plane_inlier_ratio;
  e.num_points = int64_t(m.cloud.points.size());
  e.num_keypoints = int64_t(m.keypoint_indices.size());
  e.voxel_size = m.grid.voxelSize();
  if (!m.cloud.points.empty()) {
    e.bbox_min = e.bbox_max = m.cloud.points.front();
    for (const auto& p : m.cloud.points) {
      e.bbox_min = e.bbox_min.cwiseMin(p);
      e.bbox_max = e.bbox_max.cwiseMax(p);
    }
  }
  e.grid = encodeTsdfGrid(m.grid, options);
  e.surface_voxels = encodeVoxelList(m.surface_voxels, options);
  e.cloud = encodePointCloud(m.cloud, options);
  e.keypoints = encodeIndices(m.keypoint_indices, options);
  e.descriptors = encodeDescriptors(m.descriptors, options);
  e.timings = m.timings;
  for (const auto& o : m.observations) {
    e.observations.push_back({o.session, int64_t(o.label), encodeTransform(o.T_world_object),
                              encodeTransform(o.T_object_segment)});
  }
  return e;
}

// Binds the model columns in the order of kModelColumns to parameters 1..N.
constexpr const char* kModelColumns =
    "planar, plane_inlier_ratio, num_points, num_keypoints, voxel_size, bbox_min_x, bbox_min_y, "
    "bbox_min_z, bbox_max_x, bbox_max_y, bbox_max_z, grid, surface_voxels, cloud, keypoints, "
    "descriptors, cloud_ms, planarity_ms, keypoints_ms, descriptors_ms, structure";
constexpr int kNumModelColumns = 21;

void bindModel(Statement* s, const EncodedModel& e) {
  s->bind(1, int64_t(e.planar)).bind(2, e.plane_inlier_ratio).bind(3, e.num_points);
  s->bind(4, e.num_keypoints).bind(5, e.voxel_size);
  for (int k = 0; k < 3; ++k) s->bind(6 + k, double(e.bbox_min[k]));
  for (int k = 0; k < 3; ++k) s->bind(9 + k, double(e.bbox_max[k]));
  s->bindBlob(12, e.grid).bindBlob(13, e.surface_voxels).bindBlob(14, e.cloud);
  s->bindBlob(15, e.keypoints).bindBlob(16, e.descriptors);
  s->bind(17, e.timings.cloud_ms).bind(18, e.timings.planarity_ms);
  s->bind(19, e.timings.keypoints_ms).bind(20, e.timings.descriptors_ms);
  s->bind(21, int64_t(e.structure));
}

Status duplicateSession(const Status& status, const std::string& name) {
  if (absl::IsFailedPrecondition(status)) {
    return absl::AlreadyExistsError(absl::StrFormat("session %s already exists", name));
  }
  return status;
}

}  // namespace

const char* sessionStateName(SessionState state) {
  switch (state) {
    case SessionState::kOpen: return "open";
    case SessionState::kEnded: return "ended";
    case SessionState::kInterrupted: return "interrupted";
  }
  return "open";
}

namespace {

// The scene caches: lists of (session, value), most recently used first.
template <typename Value>
std::optional<Value> cacheGet(std::list<std::pair<std::string, Value>>* cache,
                              const std::string& key) {
  for (auto it = cache->begin(); it != cache->end(); ++it) {
    if (it->first == key) {
      cache->splice(cache->begin(), *cache, it);
      return cache->front().second;
    }
  }
  return std::nullopt;
}

template <typename Value>
void cachePut(std::list<std::pair<std::string, Value>>* cache, const std::string& key,
              Value value, size_t max_entries) {
  cache->remove_if([&key](const auto& entry) { return entry.first == key; });
  cache->emplace_front(key, std::move(value));
  while (cache->size() > max_entries) cache->pop_back();
}

}  // namespace

Status SqliteStoreOptions::validate() const {
  if (synchronous != "FULL" && synchronous != "NORMAL") {
    return absl::InvalidArgumentError(
        absl::StrFormat("storage.synchronous must be FULL or NORMAL, got '%s'", synchronous));
  }
  if (!(busy_timeout_ms >= 0 && busy_timeout_ms <= 600000)) {
    return absl::InvalidArgumentError(
        absl::StrFormat("storage.busy_timeout_ms must be in [0, 600000], got %d", busy_timeout_ms));
  }
  if (!(max_cached_scenes >= 1 && max_cached_scenes <= 1024)) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "storage.max_cached_scenes must be in [1, 1024], got %d", max_cached_scenes));
  }
  if (!(max_readers >= 1 && max_readers <= 256)) {
    return absl::InvalidArgumentError(
        absl::StrFormat("storage.max_readers must be in [1, 256], got %d", max_readers));
  }
  if (!(journal_size_limit_bytes >= 0)) {
    return absl::InvalidArgumentError("storage.journal_size_limit_bytes must be >= 0");
  }
  return absl::OkStatus();
}

// A reader connection borrowed from the pool, given back when the lease ends.
class SqliteStore::ReaderLease {
 public:
  ReaderLease(const SqliteStore* store, Connection connection)
      : store_(store), connection_(std::move(connection)) {}
  ReaderLease(ReaderLease&& other) noexcept
      : store_(other.store_), connection_(std::move(other.connection_)) {
    other.store_ = nullptr;
    other.connection_.reset();
  }
  ReaderLease& operator=(ReaderLease&&) = delete;
  ~ReaderLease() {
    if (!connection_ || connection_->get() == nullptr || store_ == nullptr) return;
    std::lock_guard lock(store_->reader_mutex_);
    if (store_->idle_readers_.size() < size_t(store_->options_.max_readers)) {
      store_->idle_readers_.push_back(std::move(*connection_));
    }
  }
  const Connection& operator*() const { return *connection_; }

 private:
  const SqliteStore* store_;
  std::optional<Connection> connection_;
};

SqliteStore::SqliteStore(std::string path, SqliteStoreOptions options)
    : path_(std::move(path)), options_(std::move(options)) {}

namespace {

// The database files this process's stores have open, by (device, inode).
struct OpenFile {
  int fd = -1;       // the one descriptor of the file this process opens itself
  int stores = 0;    // registered stores
  bool writer = false;
};
std::mutex g_files_mutex;
std::map<std::pair<uint64_t, uint64_t>, OpenFile> g_files;

Status heldByAnotherWriter(const std::string& path) {
  return absl::FailedPreconditionError(absl::StrFormat(
      "%s is open for writing by another objdb store (objdb-server or objdb ingest, in this "
      "process or another); one writer at a time (readers such as `objdb db` may open it "
      "meanwhile)",
      path));
}

}  // namespace

StatusOr<FileRegistration> FileRegistration::acquire(const std::string& path, bool writer) {
  std::lock_guard lock(g_files_mutex);
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) {
    return absl::UnavailableError(absl::StrFormat("%s: %s", path, std::strerror(errno)));
  }
  const std::pair<uint64_t, uint64_t> key{uint64_t(st.st_dev), uint64_t(st.st_ino)};
  auto it = g_files.find(key);
  if (it == g_files.end()) {
    // No store of this process has the file open: no SQLite lock of ours can be dropped by
    // closing this descriptor should the lock below fail.
    const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) {
      return absl::UnavailableError(
          absl::StrFormat("opening %s: %s", path, std::strerror(errno)));
    }
    if (writer && ::flock(fd, LOCK_EX | LOCK_NB) != 0) {
      const int error = errno;
      ::close(fd);
      if (error == EWOULDBLOCK) return heldByAnotherWriter(path);
      return absl::UnavailableError(absl::StrFormat("locking %s: %s", path, std::strerror(error)));
    }
    g_files[key] = OpenFile{fd, 1, writer};
    return FileRegistration(key.first, key.second, writer);
  }
  OpenFile& file = it->second;
  if (writer) {
    if (file.writer) return heldByAnotherWriter(path);
    if (::flock(file.fd, LOCK_EX | LOCK_NB) != 0) {
      const int error = errno;
      if (error == EWOULDBLOCK) return heldByAnotherWriter(path);
      return absl::UnavailableError(absl::StrFormat("locking %s: %s", path, std::strerror(error)));
    }
    file.writer = true;
  }
  ++file.stores;
  return FileRegistration(key.first, key.second, writer);
}

FileRegistration::FileRegistration(FileRegistration&& other) noexcept
    : device_(other.device_), inode_(other.inode_), writer_(other.writer_),
      active_(other.active_) {
  other.active_ = false;
}

FileRegistration::~FileRegistration() {
  if (!active_) return;
  std::lock_guard lock(g_files_mutex);
  const auto it = g_files.find({device_, inode_});
  if (it == g_files.end()) return;
  OpenFile& file = it->second;
  if (writer_) {
    ::flock(file.fd, LOCK_UN);  // unlocking keeps the descriptor: no SQLite lock is dropped
    file.writer = false;
  }
  if (--file.stores == 0) {
    ::close(file.fd);  // the last store of this file: its connections are closed already
    g_files.erase(it);
  }
}

SqliteStore::~SqliteStore() = default;

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

Status SqliteStore::requireWriter() const {
  if (!writer_) {
    return absl::FailedPreconditionError(absl::StrFormat("%s is open read-only", path_));
  }
  return absl::OkStatus();
}

StatusOr<int64_t> SqliteStore::sessionIdForWrite(const std::string& name) {
  if (name.empty()) return absl::InvalidArgumentError("session name is empty");
  OBJDB_ASSIGN_OR_RETURN(
      Statement insert,
      Statement::prepare(*writer_, absl::StrFormat("INSERT INTO sessions(name, started_at, state) "
                                                   "VALUES (?, %s, 'open') "
                                                   "ON CONFLICT(name) DO NOTHING",
                                                   kNow)));
  OBJDB_RETURN_IF_ERROR(insert.bind(1, name).run());
  OBJDB_ASSIGN_OR_RETURN(Statement select,
                         Statement::prepare(*writer_, "SELECT id FROM sessions WHERE name = ?"));
  select.bind(1, name);
  OBJDB_ASSIGN_OR_RETURN(const bool row, select.step());
  if (!row) return absl::InternalError(absl::StrFormat("session %s vanished", name));
  return select.columnInt(0);
}

Status SqliteStore::putRawSegment(const database::RawSegmentRecord& segment) {
  if (segment.grid == nullptr) {
    return absl::InvalidArgumentError(absl::StrFormat("raw segment %s/%d has no grid",
                                                      segment.key.session, segment.key.label));
  }
  const std::string pose = encodeTransform(segment.T_world_segment);
  const std::string grid = encodeTsdfGrid(*segment.grid, options_.blobs);
  if (!segment.voxel_parts.empty() && segment.voxel_parts.size() != segment.voxels.size()) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "raw segment %s/%d: %d voxel parts for %d voxels", segment.key.session, segment.key.label,
        segment.voxel_parts.size(), segment.voxels.size()));
  }
  const std::string voxels = encodeVoxelList(segment.voxels, options_.blobs);
  const std::string voxel_parts =
      segment.voxel_parts.empty() ? std::string() : encodeIndices(segment.voxel_parts, options_.blobs);
  std::lock_guard lock(write_mutex_);
  OBJDB_RETURN_IF_ERROR(requireWriter());
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
            absl::StrFormat(
                "INSERT INTO raw_segments(session_id, label, pose, grid, voxels, "
                "extraction_frame, observation_depth_m, parts, voxel_parts, extracted_at) "
                "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, %s) "
                "ON CONFLICT(session_id, label) DO UPDATE SET pose = excluded.pose, "
                "grid = excluded.grid, voxels = excluded.voxels, "
                "extraction_frame = excluded.extraction_frame, "
                "observation_depth_m = excluded.observation_depth_m, parts = excluded.parts, "
                "voxel_parts = excluded.voxel_parts, extracted_at = excluded.extracted_at",
                kNow)));
    s.bind(1, sid).bind(2, int64_t(segment.key.label)).bindBlob(3, pose).bindBlob(4, grid);
    s.bindBlob(5, voxels).bind(6, segment.extraction_frame);
    s.bind(7, double(segment.observation_depth_m)).bind(8, absl::StrJoin(segment.parts, ","));
    if (segment.voxel_parts.empty()) {
      s.bindNull(9);
    } else {
      s.bindBlob(9, voxel_parts);
    }
    OBJDB_RETURN_IF_ERROR(s.run());
    return txn.commit();
  };
  return annotate(body(), context);
}

StatusOr<std::shared_ptr<const database::RawSegmentRecord>> SqliteStore::rawSegment(
    const database::SegmentKey& key) const {
  OBJDB_ASSIGN_OR_RETURN(ReaderLease lease, reader());
  OBJDB_ASSIGN_OR_RETURN(
      Statement s,
      Statement::prepare(*lease,
                         "SELECT r.id, r.pose, r.grid, r.voxels, r.extraction_frame, "
                         "r.observation_depth_m, r.parts, r.voxel_parts "
                         "FROM raw_segments r JOIN sessions s ON s.id = r.session_id "
                         "WHERE s.name = ? AND r.label = ?"));
  s.bind(1, key.session).bind(2, int64_t(key.label));
  OBJDB_ASSIGN_OR_RETURN(const bool row, s.step());
  if (!row) {
    return absl::NotFoundError(absl::StrFormat("no raw segment %s/%d", key.session, key.label));
  }
  const int64_t id = s.columnInt(0);
  auto record = std::make_shared<database::RawSegmentRecord>();
  record->key = key;
  auto pose = decodeTransform(s.columnBlob(1));
  if (!pose.ok()) return inRow(pose.status(), "raw_segments", id, "pose");
  record->T_world_segment = *pose;
  auto grid = decodeTsdfGrid(s.columnBlob(2));
  if (!grid.ok()) return inRow(grid.status(), "raw_segments", id, "grid");
  record->grid = std::make_shared<const tsdf::TsdfLayer>(std::move(*grid));
  auto voxels = decodeVoxelList(s.columnBlob(3));
  if (!voxels.ok()) return inRow(voxels.status(), "raw_segments", id, "voxels");
  record->voxels = std::move(*voxels);
  record->extraction_frame = s.columnInt(4);
  record->observation_depth_m = float(s.columnDouble(5));
  auto parts = parseParts(s.columnText(6));
  if (!parts.ok()) return inRow(parts.status(), "raw_segments", id, "parts");
  record->parts = std::move(*parts);
  if (!s.columnIsNull(7)) {
    auto voxel_parts = decodeIndices(s.columnBlob(7));
    if (!voxel_parts.ok()) return inRow(voxel_parts.status(), "raw_segments", id, "voxel_parts");
    if (voxel_parts->size() != record->voxels.size()) {
      return inRow(absl::DataLossError(absl::StrFormat("%d voxel parts for %d voxels",
                                                       voxel_parts->size(), record->voxels.size())),
                   "raw_segments", id, "voxel_parts");
    }
    record->voxel_parts = std::move(*voxel_parts);
  }
  return std::shared_ptr<const database::RawSegmentRecord>(std::move(record));
}

StatusOr<int64_t> SqliteStore::addModel(model::ObjectModel model) {
  const EncodedModel e = encodeModel(model, options_.blobs);
  std::lock_guard lock(write_mutex_);
  OBJDB_RETURN_IF_ERROR(requireWriter());
  auto body = [&]() -> StatusOr<int64_t> {
    OBJDB_ASSIGN_OR_RETURN(Transaction txn,
                           Transaction::begin(*writer_, Transaction::Kind::kWrite));
    std::string placeholders;
    for (int i = 0; i < kNumModelColumns; ++i) placeholders += "?, ";
    OBJDB_ASSIGN_OR_RETURN(
        Statement s,
        Statement::prepare(*writer_,
                           absl::StrFormat("INSERT INTO models(%s, state, created_at, updated_at) "
                                           "VALUES (%s'active', %s, %s)",
                                           kModelColumns, placeholders, kNow, kNow)));
    bindModel(&s, e);
    OBJDB_RETURN_IF_ERROR(s.run());
    const int64_t id = sqlite3_last_insert_rowid(writer_->get());
    OBJDB_RETURN_IF_ERROR(writeObservations(id, e, /*replace=*/false));
    OBJDB_RETURN_IF_ERROR(txn.commit());
    return id;
  };
  auto id = body();
  if (!id.ok()) return annotate(id.status(), "adding an object model");
  return id;
}

// The observation rows of model `model_id` (replacing its earlier ones when `replace`). Runs
// inside the caller's transaction.
Status SqliteStore::writeObservations(int64_t model_id, const EncodedModel& model, bool replace) {
  if (replace) {
    OBJDB_ASSIGN_OR_RETURN(Statement del, Statement::prepare(
                                              *writer_, "DELETE FROM observations WHERE model_id = ?"));
    OBJDB_RETURN_IF_ERROR(del.bind(1, model_id).run());
  }
  OBJDB_ASSIGN_OR_RETURN(
      Statement s,
      Statement::prepare(*writer_,
                         "INSERT INTO observations(model_id, seq, session_id, label, "
                         "raw_segment_id, T_world_object, T_object_segment) VALUES "
                         "(?, ?, ?, ?, (SELECT id FROM raw_segments WHERE session_id = ?3 AND "
                         "label = ?4), ?, ?)"));
  for (size_t k = 0; k < model.observations.size(); ++k) {
    const auto& o = model.observations[k];
    OBJDB_ASSIGN_OR_RETURN(const int64_t sid, sessionIdForWrite(o.session));
    OBJDB_RETURN_IF_ERROR(s.reset());
    s.bind(1, model_id).bind(2, int64_t(k)).bind(3, sid).bind(4, o.label);
    s.bindBlob(5, o.T_world_object).bindBlob(6, o.T_object_segment);
    OBJDB_RETURN_IF_ERROR(s.run());
  }
  return absl::OkStatus();
}

// Model `id`'s row and observations rewritten from `e`, with `merge` recorded when given. Runs
// inside the caller's write transaction.
Status SqliteStore::rewriteModel(const EncodedModel& e, int64_t id,
                                 const database::MergeRecord* merge) {
  std::string assignments;
  for (const absl::string_view column : absl::StrSplit(kModelColumns, ", ")) {
    absl::StrAppend(&assignments, column, " = ?, ");
  }
  OBJDB_ASSIGN_OR_RETURN(
      Statement s,
      Statement::prepare(*writer_, absl::StrFormat("UPDATE models SET %supdated_at = %s "
                                                   "WHERE id = ? AND state = 'active'",
                                                   assignments, kNow)));
  bindModel(&s, e);
  s.bind(kNumModelColumns + 1, id);
  OBJDB_RETURN_IF_ERROR(s.run());
  if (sqlite3_changes(writer_->get()) == 0) {
    return absl::NotFoundError(absl::StrFormat("no object model %d to replace", id));
  }
  OBJDB_RETURN_IF_ERROR(writeObservations(id, e, /*replace=*/true));
  if (merge == nullptr) return absl::OkStatus();
  OBJDB_ASSIGN_OR_RETURN(
      Statement m,
      Statement::prepare(*writer_,
                         absl::StrFormat("INSERT INTO merge_records(target, source, transform, "
                                         "icp_rmse_m, tsdf_rmse_m, tsdf_overlap, "
                                         "scene_checks, created_at) VALUES "
                                         "(?, ?, ?, ?, ?, ?, ?, %s)",
                                         kNow)));
  m.bind(1, merge->target).bind(2, merge->source).bindBlob(3, encodeTransform(merge->T_target_source));
  m.bind(4, merge->icp_rmse_m).bind(5, merge->tsdf_rmse_m);
  m.bind(6, int64_t(merge->tsdf_overlap)).bind(7, int64_t(merge->scene_checks));
  return m.run();
}

Status SqliteStore::replaceModel(model::ObjectModel model,
                                 const std::optional<database::MergeRecord>& merge) {
  const EncodedModel e = encodeModel(model, options_.blobs);
  std::lock_guard lock(write_mutex_);
  OBJDB_RETURN_IF_ERROR(requireWriter());
  auto body = [&]() -> Status {
    OBJDB_ASSIGN_OR_RETURN(Transaction txn,
                           Transaction::begin(*writer_, Transaction::Kind::kWrite));
    OBJDB_RETURN_IF_ERROR(rewriteModel(e, model.id, merge ? &*merge : nullptr));
    return txn.commit();
  };
  return annotate(body(), absl::StrFormat("replacing object model %d", model.id));
}

Status SqliteStore::absorbModel(model::ObjectModel target, const database::MergeRecord& merge,
                                int64_t absorbed) {
  const EncodedModel e = encodeModel(target, options_.blobs);
  std::lock_guard lock(write_mutex_);
  OBJDB_RETURN_IF_ERROR(requireWriter());
  auto body = [&]() -> Status {
    if (absorbed == target.id) {
      return absl::InvalidArgumentError("a model cannot be merged into itself");
    }
    OBJDB_ASSIGN_OR_RETURN(Transaction txn,
                           Transaction::begin(*writer_, Transaction::Kind::kWrite));
    // The absorbed row stays for lineage (state merged, merged_into the target); its geometry
    // and observations now live in the target.
    OBJDB_RETURN_IF_ERROR(retireModel(absorbed, target.id));
    OBJDB_RETURN_IF_ERROR(rewriteModel(e, target.id, &merge));
    return txn.commit();
  };
  return annotate(body(), absl::StrFormat("merging object model %d into object model %d", absorbed,
                                          target.id));
}

// Active model `id` out of the active set: state removed, or merged into `merged_into` (> 0);
// its blobs and observations dropped, its row kept. Runs inside the caller's write transaction.
Status SqliteStore::retireModel(int64_t id, int64_t merged_into) {
  OBJDB_ASSIGN_OR_RETURN(
      Statement s,
      Statement::prepare(*writer_,
                         absl::StrFormat("UPDATE models SET state = ?, merged_into = ?, "
                                         "grid = NULL, surface_voxels = NULL, cloud = NULL, "
                                         "keypoints = NULL, descriptors = NULL, updated_at = %s "
                                         "WHERE id = ? AND state = 'active'",
                                         kNow)));
  s.bind(1, std::string_view(merged_into > 0 ? "merged" : "removed"));
  if (merged_into > 0) {
    s.bind(2, merged_into);
  } else {
    s.bindNull(2);
  }
  OBJDB_RETURN_IF_ERROR(s.bind(3, id).run());
  if (sqlite3_changes(writer_->get()) == 0) {
    return absl::NotFoundError(absl::StrFormat("no object model %d to %s", id,
                                               merged_into > 0 ? "merge" : "remove"));
  }
  OBJDB_ASSIGN_OR_RETURN(Statement del, Statement::prepare(
                                            *writer_, "DELETE FROM observations WHERE model_id = ?"));
  return del.bind(1, id).run();
}

Status SqliteStore::removeModel(int64_t id) {
  std::lock_guard lock(write_mutex_);
  OBJDB_RETURN_IF_ERROR(requireWriter());
  auto body = [&]() -> Status {
    OBJDB_ASSIGN_OR_RETURN(Transaction txn,
                           Transaction::begin(*writer_, Transaction::Kind::kWrite));
    // The row stays as a tombstone (ids are never reused; merge records keep their target).
    OBJDB_RETURN_IF_ERROR(retireModel(id, 0));
    return txn.commit();
  };
  return body();
}

StatusOr<std::shared_ptr<const model::ObjectModel>> SqliteStore::model(int64_t id) const {
  OBJDB_ASSIGN_OR_RETURN(ReaderLease lease, reader());
  OBJDB_ASSIGN_OR_RETURN(Transaction snapshot, Transaction::begin(*lease, Transaction::Kind::kRead));
  OBJDB_ASSIGN_OR_RETURN(
      Statement s,
      Statement::prepare(*lease, absl::StrFormat("SELECT %s FROM models WHERE id = ? AND "
                                                 "state = 'active'",
                                                 kModelColumns)));
  s.bind(1, id);
  OBJDB_ASSIGN_OR_RETURN(const bool row, s.step());
  if (!row) return absl::NotFoundError(absl::StrFormat("no object model %d", id));
  const std::string where = absl::StrFormat("object model %d", id);
  auto grid = decodeTsdfGrid(s.columnBlob(11));
  if (!grid.ok()) return inRow(grid.status(), "models", id, "grid");
  model::ObjectModel m(std::move(*grid));
  m.id = id;
  m.planar = s.columnInt(0) != 0;
  m.plane_inlier_ratio = float(s.columnDouble(1));
  auto voxels = decodeVoxelList(s.columnBlob(12));
  if (!voxels.ok()) return inRow(voxels.status(), "models", id, "surface_voxels");
  m.surface_voxels = std::move(*voxels);
  auto cloud = decodePointCloud(s.columnBlob(13));
  if (!cloud.ok()) return inRow(cloud.status(), "models", id, "cloud");
  m.cloud = std::move(*cloud);
  auto keypoints = decodeIndices(s.columnBlob(14));
  if (!keypoints.ok()) return inRow(keypoints.status(), "models", id, "keypoints");
  m.keypoint_indices = std::move(*keypoints);
  auto descriptors = decodeDescriptors(s.columnBlob(15));
  if (!descriptors.ok()) return inRow(descriptors.status(), "models", id, "descriptors");
  m.descriptors = std::move(*descriptors);
  m.timings = {s.columnDouble(16), s.columnDouble(17), s.columnDouble(18), s.columnDouble(19)};
  m.structure = s.columnInt(20) != 0;
  for (uint32_t k : m.keypoint_indices) {
    if (k >= m.cloud.points.size()) {
      return absl::DataLossError(absl::StrFormat(
          "%s: keypoint index %d beyond its %d cloud points", where, k, m.cloud.points.size()));
    }
  }
  if (m.descriptors.size() != m.keypoint_indices.size() && !m.descriptors.empty()) {
    return absl::DataLossError(absl::StrFormat("%s: %d descriptors for %d keypoints", where,
                                               m.descriptors.size(), m.keypoint_indices.size()));
  }
  OBJDB_ASSIGN_OR_RETURN(
      Statement o,
      Statement::prepare(*lease,
                         "SELECT o.rowid, s.name, o.label, o.T_world_object, o.T_object_segment "
                         "FROM observations o JOIN sessions s ON s.id = o.session_id "
                         "WHERE o.model_id = ? ORDER BY o.seq"));
  o.bind(1, id);
  while (true) {
    OBJDB_ASSIGN_OR_RETURN(const bool more, o.step());
    if (!more) break;
    model::Observation obs;
    obs.session = o.columnText(1);
    obs.label = uint32_t(o.columnInt(2));
    auto T_wo = decodeTransform(o.columnBlob(3));
    if (!T_wo.ok()) return inRow(T_wo.status(), "observations", o.columnInt(0), "T_world_object");
    auto T_os = decodeTransform(o.columnBlob(4));
    if (!T_os.ok()) return inRow(T_os.status(), "observations", o.columnInt(0), "T_object_segment");
    obs.T_world_object = *T_wo;
    obs.T_object_segment = *T_os;
    m.observations.push_back(std::move(obs));
  }
  OBJDB_RETURN_IF_ERROR(snapshot.commit());
  return std::shared_ptr<const model::ObjectModel>(
      std::make_shared<model::ObjectModel>(std::move(m)));
}

StatusOr<std::vector<ModelSummary>> SqliteStore::modelSummaries(const ModelQuery& query) const {
  OBJDB_ASSIGN_OR_RETURN(ReaderLease lease, reader());
  OBJDB_ASSIGN_OR_RETURN(Transaction snapshot, Transaction::begin(*lease, Transaction::Kind::kRead));
  std::string where = query.include_merged ? "m.state IN ('active', 'merged')" : "m.state = 'active'";
  if (!query.include_structure) where += " AND m.structure = 0";
  if (!query.session.empty()) {
    where += " AND m.id IN (SELECT o.model_id FROM observations o JOIN sessions s ON "
             "s.id = o.session_id WHERE s.name = ?2)";
  }
  OBJDB_ASSIGN_OR_RETURN(
      Statement s,
      Statement::prepare(
          *lease,
          absl::StrFormat("SELECT m.id, m.state, COALESCE(m.merged_into, 0), m.planar, "
                          "m.num_points, m.num_keypoints, COALESCE(m.voxel_size, 0), "
                          "COALESCE(m.bbox_min_x, 0), COALESCE(m.bbox_min_y, 0), "
                          "COALESCE(m.bbox_min_z, 0), COALESCE(m.bbox_max_x, 0), "
                          "COALESCE(m.bbox_max_y, 0), COALESCE(m.bbox_max_z, 0), "
                          "(SELECT COUNT(*) FROM merge_records r WHERE r.target = m.id), "
                          "m.structure "
                          "FROM models m WHERE m.id > ?1 AND %s ORDER BY m.id LIMIT ?3",
                          where)));
  s.bind(1, query.after_id);
  if (!query.session.empty()) s.bind(2, query.session);
  s.bind(3, int64_t(std::min<size_t>(query.limit, size_t(1) << 30)));
  std::vector<ModelSummary> out;
  while (true) {
    OBJDB_ASSIGN_OR_RETURN(const bool row, s.step());
    if (!row) break;
    ModelSummary m;
    m.id = s.columnInt(0);
    m.state = s.columnText(1);
    m.merged_into = s.columnInt(2);
    m.planar = s.columnInt(3) != 0;
    m.num_points = s.columnInt(4);
    m.num_keypoints = s.columnInt(5);
    m.voxel_size = s.columnDouble(6);
    for (int k = 0; k < 3; ++k) {
      m.bbox_min[k] = s.columnDouble(7 + k);
      m.bbox_max[k] = s.columnDouble(10 + k);
    }
    m.merges = s.columnInt(13);
    m.structure = s.columnInt(14) != 0;
    out.push_back(std::move(m));
  }
  OBJDB_ASSIGN_OR_RETURN(
      Statement o,
      Statement::prepare(*lease,
                         "SELECT o.rowid, s.name, o.label, COALESCE(o.raw_segment_id, 0), "
                         "o.T_world_object, COALESCE(r.parts, '') FROM observations o JOIN "
                         "sessions s ON s.id = o.session_id LEFT JOIN raw_segments r ON "
                         "r.id = o.raw_segment_id WHERE o.model_id = ? ORDER BY o.seq"));
  for (ModelSummary& m : out) {
    OBJDB_RETURN_IF_ERROR(o.reset());
    o.bind(1, m.id);
    while (true) {
      OBJDB_ASSIGN_OR_RETURN(const bool more, o.step());
      if (!more) break;
      auto T_wo = decodeTransform(o.columnBlob(4));
      if (!T_wo.ok()) return inRow(T_wo.status(), "observations", o.columnInt(0), "T_world_object");
      auto parts = parseParts(o.columnText(5));
      if (!parts.ok()) return inRow(parts.status(), "raw_segments", o.columnInt(3), "parts");
      m.observations.push_back(
          {o.columnText(1), uint32_t(o.columnInt(2)), o.columnInt(3), *T_wo, std::move(*parts)});
    }
  }
  OBJDB_RETURN_IF_ERROR(snapshot.commit());
  return out;
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

StatusOr<std::vector<int64_t>> SqliteStore::modelIds() const {
  OBJDB_ASSIGN_OR_RETURN(ReaderLease lease, reader());
  OBJDB_ASSIGN_OR_RETURN(
      Statement s,
      Statement::prepare(*lease, "SELECT id FROM models WHERE state = 'active' ORDER BY id"));
  std::vector<int64_t> ids;
  while (true) {
    OBJDB_ASSIGN_OR_RETURN(const bool row, s.step());
    if (!row) break;
    ids.push_back(s.columnInt(0));
  }
  return ids;
}

StatusOr<database::MatchEntries> SqliteStore::matchEntries() const {
  OBJDB_ASSIGN_OR_RETURN(ReaderLease lease, reader());
  OBJDB_ASSIGN_OR_RETURN(Transaction snapshot, Transaction::begin(*lease, Transaction::Kind::kRead));
  OBJDB_ASSIGN_OR_RETURN(
      Statement s,
      Statement::prepare(*lease,
                         "SELECT id, planar, num_points, num_keypoints, descriptors, structure "
                         "FROM models WHERE state = 'active' ORDER BY id"));
  database::MatchEntries out;
  std::map<int64_t, size_t> slot;
  while (true) {
    OBJDB_ASSIGN_OR_RETURN(const bool row, s.step());
    if (!row) break;
    database::MatchEntry e;
    e.id = s.columnInt(0);
    e.planar = s.columnInt(1) != 0;
    e.structure = s.columnInt(5) != 0;
    e.num_points = size_t(s.columnInt(2));
    e.num_keypoints = size_t(s.columnInt(3));
    auto descriptors = decodeDescriptors(s.columnBlob(4));
    if (!descriptors.ok()) {
      out.skipped.push_back(inRow(descriptors.status(), "models", e.id, "descriptors"));
      continue;
    }
    e.descriptors = std::move(*descriptors);
    slot[e.id] = out.entries.size();
    out.entries.push_back(std::move(e));
  }
  OBJDB_ASSIGN_OR_RETURN(
      Statement o,
      Statement::prepare(*lease,
                         "SELECT o.model_id, s.name, o.label FROM observations o "
                         "JOIN sessions s ON s.id = o.session_id ORDER BY o.model_id, o.seq"));
  while (true) {
    OBJDB_ASSIGN_OR_RETURN(const bool row, o.step());
    if (!row) break;
    const auto it = slot.find(o.columnInt(0));
    if (it == slot.end()) continue;
    out.entries[it->second].segments.push_back({o.columnText(1), uint32_t(o.columnInt(2))});
  }
  OBJDB_RETURN_IF_ERROR(snapshot.commit());
  return out;
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
  OBJDB_ASSIGN_OR_RETURN(
      Statement s,
      Statement::prepare(*lease, absl::StrFormat("SELECT id, target, source, transform, "
                                                 "icp_rmse_m, tsdf_rmse_m, tsdf_overlap, "
                                                 "scene_checks FROM merge_records %s ORDER BY id",
                                                 target ? "WHERE target = ?" : "")));
  if (target) s.bind(1, *target);
  std::vector<database::MergeRecord> records;
  while (true) {
    OBJDB_ASSIGN_OR_RETURN(const bool row, s.step());
    if (!row) break;
    database::MergeRecord r;
    r.target = s.columnInt(1);
    r.source = s.columnText(2);
    auto T = decodeTransform(s.columnBlob(3));
    if (!T.ok()) return inRow(T.status(), "merge_records", s.columnInt(0), "transform");
    r.T_target_source = *T;
    r.icp_rmse_m = s.columnDouble(4);
    r.tsdf_rmse_m = s.columnDouble(5);
    r.tsdf_overlap = size_t(s.columnInt(6));
    r.scene_checks = size_t(s.columnInt(7));
    records.push_back(std::move(r));
  }
  return records;
}

Status SqliteStore::writeMap(const MapTables& tables, const std::string& session,
                             const tsdf::TsdfLayer& scene, const gsm::LabelBlocks* labels,
                             int64_t frames) {
  struct EncodedBlock {
    tsdf::BlockIndex index;
    std::string blob;
  };
  std::vector<EncodedBlock> blocks;
  blocks.reserve(scene.numBlocks());
  for (const auto& [index, block] : scene.blocks()) {
    blocks.push_back({index, encodeTsdfBlock(*block, options_.blobs)});
  }
  std::vector<EncodedBlock> label_blocks;
  if (labels != nullptr) {
    const size_t voxels = size_t(scene.voxelsPerSide()) * scene.voxelsPerSide() *
                          scene.voxelsPerSide();
    for (const auto& [index, block] : *labels) {
      if (block.size() != voxels) {
        return absl::InvalidArgumentError(absl::StrFormat(
            "%s of session %s: label block (%d, %d, %d) has %d labels, the grid's blocks %d",
            tables.what, session, index.x(), index.y(), index.z(), block.size(), voxels));
      }
      label_blocks.push_back({index, encodeLabelBlock(block, options_.blobs)});
    }
  }
  std::lock_guard lock(write_mutex_);
  OBJDB_RETURN_IF_ERROR(requireWriter());
  OBJDB_ASSIGN_OR_RETURN(Transaction txn, Transaction::begin(*writer_, Transaction::Kind::kWrite));
  OBJDB_ASSIGN_OR_RETURN(const int64_t sid, sessionIdForWrite(session));
  OBJDB_ASSIGN_OR_RETURN(
      Statement map,
      Statement::prepare(*writer_,
                         absl::StrFormat("INSERT INTO %s(session_id, voxel_size, voxels_per_side, "
                                         "blocks, updated_at) VALUES (?, ?, ?, ?, %s) "
                                         "ON CONFLICT(session_id) DO UPDATE "
                                         "SET voxel_size = excluded.voxel_size, "
                                         "voxels_per_side = excluded.voxels_per_side, "
                                         "blocks = excluded.blocks, "
                                         "updated_at = excluded.updated_at",
                                         tables.maps, kNow)));
  map.bind(1, sid).bind(2, double(scene.voxelSize())).bind(3, int64_t(scene.voxelsPerSide()));
  OBJDB_RETURN_IF_ERROR(map.bind(4, int64_t(blocks.size())).run());
  if (tables.has_frames) {
    OBJDB_ASSIGN_OR_RETURN(
        Statement count,
        Statement::prepare(*writer_, absl::StrFormat("UPDATE %s SET frames = ? WHERE session_id = ?",
                                                     tables.maps)));
    OBJDB_RETURN_IF_ERROR(count.bind(1, frames).bind(2, sid).run());
  }
  // A block table's rows of this session replaced by `rows` (TSDF or label blocks).
  auto replaceBlocks = [&](const char* table, const char* column,
                           const std::vector<EncodedBlock>& rows) -> Status {
    OBJDB_ASSIGN_OR_RETURN(
        Statement del,
        Statement::prepare(*writer_, absl::StrFormat("DELETE FROM %s WHERE session_id = ?", table)));
    OBJDB_RETURN_IF_ERROR(del.bind(1, sid).run());
    OBJDB_ASSIGN_OR_RETURN(
        Statement insert,
        Statement::prepare(*writer_, absl::StrFormat("INSERT INTO %s(session_id, bx, by, bz, %s) "
                                                     "VALUES (?, ?, ?, ?, ?)",
                                                     table, column)));
    for (const auto& b : rows) {
      OBJDB_RETURN_IF_ERROR(insert.reset());
      insert.bind(1, sid).bind(2, int64_t(b.index.x())).bind(3, int64_t(b.index.y()));
      OBJDB_RETURN_IF_ERROR(insert.bind(4, int64_t(b.index.z())).bindBlob(5, b.blob).run());
    }
    return absl::OkStatus();
  };
  OBJDB_RETURN_IF_ERROR(replaceBlocks(tables.blocks, "tsdf", blocks));
  OBJDB_RETURN_IF_ERROR(replaceBlocks(tables.label_blocks, "labels", label_blocks));
  return txn.commit();
}

Status SqliteStore::putScene(const std::string& session,
                             std::shared_ptr<const tsdf::TsdfLayer> scene,
                             std::shared_ptr<const gsm::LabelBlocks> labels) {
  if (scene == nullptr) {
    return absl::InvalidArgumentError(absl::StrFormat("scene of session %s is null", session));
  }
  OBJDB_RETURN_IF_ERROR(annotate(writeMap(kSceneTables, session, *scene, labels.get(),
                                          /*frames=*/0),
                                 absl::StrFormat("storing the scene of session %s", session)));
  std::lock_guard cache_lock(scene_mutex_);
  const size_t max = size_t(options_.max_cached_scenes);
  cachePut(&scene_cache_, session, std::move(scene), max);
  cachePut(&label_cache_, session, std::move(labels), max);
  return absl::OkStatus();
}

Status SqliteStore::putSavedMap(const std::string& session, int64_t frames,
                                const tsdf::TsdfLayer& map, const gsm::LabelBlocks& labels) {
  return annotate(writeMap(kSavedTables, session, map, &labels, frames),
                  absl::StrFormat("saving the live map of session %s", session));
}

StatusOr<SavedMap> SqliteStore::savedMap(const std::string& session) const {
  SavedMap saved;
  OBJDB_ASSIGN_OR_RETURN(ReaderLease lease, reader());
  OBJDB_ASSIGN_OR_RETURN(Transaction snapshot, Transaction::begin(*lease, Transaction::Kind::kRead));
  OBJDB_ASSIGN_OR_RETURN(saved.map, readMapTsdf(*lease, kSavedTables, session, &saved.frames));
  OBJDB_ASSIGN_OR_RETURN(saved.labels, readMapLabels(*lease, kSavedTables, session));
  OBJDB_RETURN_IF_ERROR(snapshot.commit());
  return saved;
}

StatusOr<std::shared_ptr<const gsm::LabelBlocks>> SqliteStore::readMapLabels(
    const Connection& connection, const MapTables& tables, const std::string& session) const {
  OBJDB_ASSIGN_OR_RETURN(
      Statement b,
      Statement::prepare(connection,
                         absl::StrFormat("SELECT l.rowid, l.bx, l.by, l.bz, l.labels, "
                                         "m.voxels_per_side FROM %s l JOIN %s m ON m.session_id "
                                         "= l.session_id JOIN sessions s ON s.id = l.session_id "
                                         "WHERE s.name = ?",
                                         tables.label_blocks, tables.maps)));
  b.bind(1, session);
  auto labels = std::make_shared<gsm::LabelBlocks>();
  while (true) {
    OBJDB_ASSIGN_OR_RETURN(const bool row, b.step());
    if (!row) break;
    const tsdf::BlockIndex index(int(b.columnInt(1)), int(b.columnInt(2)), int(b.columnInt(3)));
    auto decoded = decodeLabelBlock(b.columnBlob(4));
    const int64_t vps = b.columnInt(5);
    if (decoded.ok() && decoded->size() != size_t(vps * vps * vps)) {
      decoded = absl::DataLossError(absl::StrFormat("%d labels, expected %d", decoded->size(),
                                                    vps * vps * vps));
    }
    if (!decoded.ok()) {
      return annotate(decoded.status(),
                      absl::StrFormat("%s labels of session %s, block (%d, %d, %d) (%s row %d)",
                                      tables.what, session, index.x(), index.y(), index.z(),
                                      tables.label_blocks, b.columnInt(0)));
    }
    labels->emplace(index, std::move(*decoded));
  }
  std::shared_ptr<const gsm::LabelBlocks> out;
  if (!labels->empty()) out = std::move(labels);
  return out;
}

StatusOr<std::shared_ptr<const tsdf::TsdfLayer>> SqliteStore::readMapTsdf(
    const Connection& connection, const MapTables& tables, const std::string& session,
    int64_t* frames) const {
  OBJDB_ASSIGN_OR_RETURN(
      Statement m,
      Statement::prepare(connection,
                         absl::StrFormat("SELECT m.session_id, m.voxel_size, m.voxels_per_side, "
                                         "%s FROM %s m JOIN sessions s ON s.id = "
                                         "m.session_id WHERE s.name = ?",
                                         tables.has_frames ? "m.frames" : "0", tables.maps)));
  m.bind(1, session);
  OBJDB_ASSIGN_OR_RETURN(const bool found, m.step());
  if (!found) return std::shared_ptr<const tsdf::TsdfLayer>();
  const int64_t sid = m.columnInt(0);
  const int vps = int(m.columnInt(2));
  if (frames != nullptr) *frames = m.columnInt(3);
  auto layer = tsdf::TsdfLayer::create(float(m.columnDouble(1)), vps);
  if (!layer.ok()) {
    return absl::DataLossError(absl::StrFormat("%s of session %s: %s", tables.what, session,
                                               layer.status().message()));
  }
  OBJDB_ASSIGN_OR_RETURN(
      Statement b,
      Statement::prepare(connection, absl::StrFormat("SELECT rowid, bx, by, bz, tsdf FROM %s "
                                                     "WHERE session_id = ?",
                                                     tables.blocks)));
  b.bind(1, sid);
  while (true) {
    OBJDB_ASSIGN_OR_RETURN(const bool row, b.step());
    if (!row) break;
    const tsdf::BlockIndex index(int(b.columnInt(1)), int(b.columnInt(2)), int(b.columnInt(3)));
    tsdf::TsdfBlock& block = layer->allocateBlock(index);
    const Status decoded = decodeTsdfBlock(b.columnBlob(4), vps, &block);
    if (!decoded.ok()) {
      return annotate(decoded, absl::StrFormat("%s of session %s, block (%d, %d, %d) (%s row %d)",
                                               tables.what, session, index.x(), index.y(), index.z(),
                                               tables.blocks, b.columnInt(0)));
    }
  }
  return std::make_shared<const tsdf::TsdfLayer>(std::move(*layer));
}

StatusOr<std::shared_ptr<const gsm::LabelBlocks>> SqliteStore::sceneLabels(
    const std::string& session) const {
  {
    std::lock_guard lock(scene_mutex_);
    if (auto cached = cacheGet(&label_cache_, session)) return *cached;
  }
  OBJDB_ASSIGN_OR_RETURN(ReaderLease lease, reader());
  OBJDB_ASSIGN_OR_RETURN(std::shared_ptr<const gsm::LabelBlocks> out,
                         readMapLabels(*lease, kSceneTables, session));
  std::lock_guard lock(scene_mutex_);
  cachePut(&label_cache_, session, out, size_t(options_.max_cached_scenes));
  return out;
}

StatusOr<std::shared_ptr<const tsdf::TsdfLayer>> SqliteStore::scene(
    const std::string& session) const {
  {
    std::lock_guard lock(scene_mutex_);
    if (auto cached = cacheGet(&scene_cache_, session)) return *cached;
  }
  OBJDB_ASSIGN_OR_RETURN(ReaderLease lease, reader());
  OBJDB_ASSIGN_OR_RETURN(Transaction snapshot, Transaction::begin(*lease, Transaction::Kind::kRead));
  OBJDB_ASSIGN_OR_RETURN(std::shared_ptr<const tsdf::TsdfLayer> shared,
                         readMapTsdf(*lease, kSceneTables, session, nullptr));
  OBJDB_RETURN_IF_ERROR(snapshot.commit());
  if (shared == nullptr) return shared;  // no scene stored (not cached: it may come)
  std::lock_guard lock(scene_mutex_);
  cachePut(&scene_cache_, session, shared, size_t(options_.max_cached_scenes));
  return shared;
}

StatusOr<SessionInfo> SqliteStore::beginSession(const SessionInfo& info) {
  if (info.name.empty()) return absl::InvalidArgumentError("session name is empty");
  std::lock_guard lock(write_mutex_);
  OBJDB_RETURN_IF_ERROR(requireWriter());
  OBJDB_ASSIGN_OR_RETURN(Transaction txn, Transaction::begin(*writer_, Transaction::Kind::kWrite));
  OBJDB_ASSIGN_OR_RETURN(
      Statement s,
      Statement::prepare(*writer_, absl::StrFormat("INSERT INTO sessions(name, intrinsics, params, "
                                                   "started_at, state) VALUES (?, ?, ?, %s, 'open')",
                                                   kNow)));
  s.bind(1, info.name).bind(2, info.intrinsics_json).bind(3, info.params_json);
  OBJDB_RETURN_IF_ERROR(duplicateSession(s.run(), info.name));
  const int64_t id = sqlite3_last_insert_rowid(writer_->get());
  OBJDB_RETURN_IF_ERROR(txn.commit());
  SessionInfo out = info;
  out.id = id;
  out.state = SessionState::kOpen;
  return out;
}

Status SqliteStore::finishSession(const std::string& name, SessionState state, int64_t frames) {
  std::lock_guard lock(write_mutex_);
  OBJDB_RETURN_IF_ERROR(requireWriter());
  OBJDB_ASSIGN_OR_RETURN(
      Statement s,
      Statement::prepare(*writer_, absl::StrFormat("UPDATE sessions SET state = ?, frames = ?, "
                                                   "ended_at = %s WHERE name = ?",
                                                   kNow)));
  s.bind(1, std::string_view(sessionStateName(state))).bind(2, frames).bind(3, name);
  OBJDB_ASSIGN_OR_RETURN(Transaction txn, Transaction::begin(*writer_, Transaction::Kind::kWrite));
  OBJDB_RETURN_IF_ERROR(s.run());
  if (sqlite3_changes(writer_->get()) == 0) {
    return absl::NotFoundError(absl::StrFormat("no session %s", name));
  }
  // Its scene map is stored: the saved live map has served its purpose.
  if (state == SessionState::kEnded) OBJDB_RETURN_IF_ERROR(deleteSavedMap(name));
  return txn.commit();
}

Status SqliteStore::deleteSavedMap(const std::string& session) {
  for (const char* table : {kSavedTables.label_blocks, kSavedTables.blocks, kSavedTables.maps}) {
    OBJDB_ASSIGN_OR_RETURN(
        Statement del,
        Statement::prepare(*writer_, absl::StrFormat("DELETE FROM %s WHERE session_id = "
                                                     "(SELECT id FROM sessions WHERE name = ?)",
                                                     table)));
    OBJDB_RETURN_IF_ERROR(del.bind(1, session).run());
  }
  return absl::OkStatus();
}

Status SqliteStore::dropSavedMap(const std::string& session) {
  std::lock_guard lock(write_mutex_);
  OBJDB_RETURN_IF_ERROR(requireWriter());
  auto body = [&]() -> Status {
    OBJDB_ASSIGN_OR_RETURN(Transaction txn,
                           Transaction::begin(*writer_, Transaction::Kind::kWrite));
    OBJDB_RETURN_IF_ERROR(deleteSavedMap(session));
    return txn.commit();
  };
  return annotate(body(), absl::StrFormat("deleting the saved map of session %s", session));
}

StatusOr<int64_t> SqliteStore::savedMapFrames(const std::string& session) const {
  OBJDB_ASSIGN_OR_RETURN(ReaderLease lease, reader());
  OBJDB_ASSIGN_OR_RETURN(
      Statement s, Statement::prepare(*lease, "SELECT m.frames FROM saved_maps m JOIN sessions s "
                                              "ON s.id = m.session_id WHERE s.name = ?"));
  s.bind(1, session);
  OBJDB_ASSIGN_OR_RETURN(const bool found, s.step());
  return found ? s.columnInt(0) : int64_t{-1};
}

std::string intrinsicsJson(const Intrinsics& intrinsics) {
  return nlohmann::json{{"width", intrinsics.width}, {"height", intrinsics.height},
                        {"fx", intrinsics.fx},       {"fy", intrinsics.fy},
                        {"cx", intrinsics.cx},       {"cy", intrinsics.cy}}
      .dump();
}

StatusOr<std::vector<SessionInfo>> SqliteStore::sessions() const {
  OBJDB_ASSIGN_OR_RETURN(ReaderLease lease, reader());
  OBJDB_ASSIGN_OR_RETURN(
      Statement s,
      Statement::prepare(*lease, "SELECT id, name, intrinsics, params, started_at, "
                                 "COALESCE(ended_at, ''), state, frames FROM sessions ORDER BY id"));
  std::vector<SessionInfo> out;
  while (true) {
    OBJDB_ASSIGN_OR_RETURN(const bool row, s.step());
    if (!row) break;
    SessionInfo info;
    info.id = s.columnInt(0);
    info.name = s.columnText(1);
    info.intrinsics_json = s.columnText(2);
    info.params_json = s.columnText(3);
    info.started_at = s.columnText(4);
    info.ended_at = s.columnText(5);
    const std::string state = s.columnText(6);
    info.state = state == "ended"         ? SessionState::kEnded
                 : state == "interrupted" ? SessionState::kInterrupted
                                          : SessionState::kOpen;
    info.frames = s.columnInt(7);
    out.push_back(std::move(info));
  }
  return out;
}

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
      if (line != "ok") report.sqlite_findings.push_back(line);
    }
    OBJDB_ASSIGN_OR_RETURN(Statement fk, Statement::prepare(*lease, "PRAGMA foreign_key_check"));
    while (true) {
      OBJDB_ASSIGN_OR_RETURN(const bool row, fk.step());
      if (!row) break;
      report.sqlite_findings.push_back(absl::StrFormat(
          "foreign key: %s row %d refers to a missing %s row", fk.columnText(0), fk.columnInt(1),
          fk.columnText(2)));
    }
  }
  using Decoder = std::function<Status(std::string_view)>;
  struct Column {
    const char* table;
    const char* column;
    Decoder decode;
  };
  const std::vector<Column> columns = {
      {"models", "grid", [](auto b) { return decodeTsdfGrid(b).status(); }},
      {"models", "surface_voxels", [](auto b) { return decodeVoxelList(b).status(); }},
      {"models", "cloud", [](auto b) { return decodePointCloud(b).status(); }},
      {"models", "keypoints", [](auto b) { return decodeIndices(b).status(); }},
      {"models", "descriptors", [](auto b) { return decodeDescriptors(b).status(); }},
      {"observations", "T_world_object", [](auto b) { return decodeTransform(b).status(); }},
      {"observations", "T_object_segment", [](auto b) { return decodeTransform(b).status(); }},
      {"raw_segments", "pose", [](auto b) { return decodeTransform(b).status(); }},
      {"raw_segments", "grid", [](auto b) { return decodeTsdfGrid(b).status(); }},
      {"raw_segments", "voxels", [](auto b) { return decodeVoxelList(b).status(); }},
      {"raw_segments", "voxel_parts", [](auto b) { return decodeIndices(b).status(); }},
      {"merge_records", "transform", [](auto b) { return decodeTransform(b).status(); }},
      {"scene_label_blocks", "labels", [](auto b) { return decodeLabelBlock(b).status(); }},
      {"saved_label_blocks", "labels", [](auto b) { return decodeLabelBlock(b).status(); }},
  };
  for (const auto& c : columns) {
    OBJDB_ASSIGN_OR_RETURN(
        Statement s,
        Statement::prepare(*lease, absl::StrFormat("SELECT rowid, %s FROM %s WHERE %s IS NOT NULL "
                                                   "ORDER BY rowid",
                                                   c.column, c.table, c.column)));
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
  for (const MapTables* tables : {&kSceneTables, &kSavedTables}) {
    OBJDB_ASSIGN_OR_RETURN(
        Statement blocks,
        Statement::prepare(*lease, absl::StrFormat("SELECT b.rowid, m.voxels_per_side, b.tsdf "
                                                   "FROM %s b JOIN %s m ON m.session_id = "
                                                   "b.session_id ORDER BY b.rowid",
                                                   tables->blocks, tables->maps)));
    while (true) {
      OBJDB_ASSIGN_OR_RETURN(const bool row, blocks.step());
      if (!row) break;
      ++report.blobs_checked;
      const int vps = int(blocks.columnInt(1));
      if (!(vps >= 2 && vps <= 64)) {
        report.damaged.push_back({tables->blocks, blocks.columnInt(0), "tsdf",
                                  absl::StrFormat("map has %d voxels per side", vps)});
        continue;
      }
      tsdf::TsdfBlock block(vps);
      const Status status = decodeTsdfBlock(blocks.columnBlob(2), vps, &block);
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
    if (named != 0) {
      copied = errno == EEXIST
                   ? absl::AlreadyExistsError(absl::StrFormat(
                         "backup: %s appeared while the copy was made; it was left alone", path))
                   : absl::UnavailableError(absl::StrFormat("backup: naming the copy %s: %s",
                                                            path, std::strerror(errno)));
    }
  }
  removeDatabaseFiles(partial);
  if (!copied.ok()) return copied;
  // The new name survives a power loss only once its directory is synced.
  const std::string directory = std::filesystem::path(path).parent_path().string();
  const int dir_fd = ::open(directory.empty() ? "." : directory.c_str(), O_RDONLY | O_CLOEXEC);
  if (dir_fd >= 0) {
    ::fsync(dir_fd);
    ::close(dir_fd);
  }
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
  const std::vector<std::pair<const char*, const char*>> tables = {
      {"sessions", "0"},
      {"scene_blocks", "length(tsdf)"},
      {"scene_label_blocks", "length(labels)"},
      {"saved_blocks", "length(tsdf)"},
      {"saved_label_blocks", "length(labels)"},
      {"raw_segments", "length(pose) + length(grid) + length(voxels)"},
      {"models",
       "COALESCE(length(grid), 0) + COALESCE(length(surface_voxels), 0) + "
       "COALESCE(length(cloud), 0) + COALESCE(length(keypoints), 0) + "
       "COALESCE(length(descriptors), 0)"},
      {"observations", "length(T_world_object) + length(T_object_segment)"},
      {"merge_records", "length(transform)"},
  };
  for (const auto& [table, bytes] : tables) {
    OBJDB_ASSIGN_OR_RETURN(
        Statement s, Statement::prepare(*lease, absl::StrFormat(
                                                    "SELECT COUNT(*), COALESCE(SUM(%s), 0) FROM %s",
                                                    bytes, table)));
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
  std::lock_guard lock(write_mutex_);
  OBJDB_RETURN_IF_ERROR(requireWriter());
  return writer_->exec("PRAGMA wal_checkpoint(TRUNCATE)", "checkpointing the WAL");
}

}  // namespace objdb::storage
