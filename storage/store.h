// The server's storage interface (docs/storage.md): core/database's ModelStore plus what
// the service needs beyond it — sessions, saved live maps, model listings, checks, statistics,
// checkpoints and online backups — and the plain value types those use. Backends implement it:
// storage/sqlite/ (SqliteStore, one embedded file) and storage/postgres/ (PostgresStore, a
// database several servers may share); storage/open_store.h opens one by its target.
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "core/common/intrinsics.h"
#include "core/common/status.h"
#include "core/common/transform.h"
#include "core/database/model_store.h"
#include "storage/blob_codec.h"

namespace objdb::storage {

enum class SessionState { kOpen, kEnded, kInterrupted };
const char* sessionStateName(SessionState state);
// The state of a stored name (anything unknown reads as open).
SessionState sessionStateFromName(std::string_view name);

// SessionInfo::intrinsics_json of `intrinsics`: {"width", "height", "fx", "fy", "cx", "cy"}.
std::string intrinsicsJson(const Intrinsics& intrinsics);

struct SessionInfo {
  int64_t id = 0;
  std::string name;
  std::string intrinsics_json;  // as the client sent them
  std::string params_json;      // effective parameters of the session
  std::string started_at, ended_at;  // ISO-8601 UTC; ended_at empty while open
  SessionState state = SessionState::kOpen;
  int64_t frames = 0;
  std::string client_info;  // the client's description of itself (its header's)
  // The server's running counters of the session as it last stored them (JSON, the server's
  // format): at each saved map, when its stream broke, when it ended. Empty: never stored (a
  // crash before any of those, or a database from before schema 6): unknown, not zero.
  std::string counters_json;
};

// An open session's map as the server last saved it: its TSDF and main labels after `frames`
// frames. `map` is null when none is saved.
struct SavedMap {
  int64_t frames = 0;
  std::shared_ptr<const tsdf::TsdfLayer> map;
  std::shared_ptr<const gsm::LabelBlocks> labels;
};

// A blob (or a row) that could not be read back.
struct Damage {
  std::string table;
  int64_t row = 0;       // rowid / model id
  std::string column;
  std::string problem;
};

struct CheckReport {
  // The database engine's own integrity findings (SQLite: PRAGMA integrity_check lines other
  // than "ok", and foreign key violations).
  std::vector<std::string> engine_findings;
  std::vector<Damage> damaged;              // blobs failing their checks
  size_t blobs_checked = 0;
  bool ok() const { return engine_findings.empty() && damaged.empty(); }
};

struct TableStats {
  std::string table;
  int64_t rows = 0;
  int64_t blob_bytes = 0;  // sum of blob lengths in the table
};

struct StoreStats {
  int schema_version = 0;
  int64_t file_bytes = 0;  // SQLite: page_count · page_size (WAL not included)
  int64_t active_models = 0, removed_models = 0, merged_models = 0;
  std::vector<TableStats> tables;
};

struct BackupReport {
  int64_t pages = 0;
  int64_t bytes = 0;  // pages · page size
};

// One model's row without its blobs, with its observations: what listings need (ListObjects,
// GetObject), cheap to read for many models.
struct ModelSummary {
  struct Pose {
    std::string session;
    uint32_t label = 0;           // GSM label of the observing raw segment
    int64_t raw_segment_id = 0;   // raw_segments row (0 when the segment row is gone)
    Transform T_world_object = Transform::Identity();
    std::vector<uint32_t> parts;  // the raw segment's GSM labels (its object's parts), sorted
  };
  int64_t id = 0;
  std::string state;             // "active" or "merged" (removed models are never listed)
  int64_t merged_into = 0;       // state "merged": the model that absorbed it
  bool planar = false;
  bool structure = false;        // room structure (core/model/structure.h): never matched
  int64_t num_points = 0, num_keypoints = 0;
  double voxel_size = 0.0;
  Eigen::Vector3d bbox_min = Eigen::Vector3d::Zero(), bbox_max = Eigen::Vector3d::Zero();  // model frame
  std::vector<Pose> observations;  // insertion order
  int64_t merges = 0;              // merge records with this model as target
};

// What became of a model id (Store::modelFate).
struct ModelFate {
  std::string state;  // "active", "merged", "removed"; empty: no model ever had this id
  // merged: the model that absorbed it; removed: the model that holds its segment now (0:
  // none, or not recorded: the segment was withdrawn, or holds no surface any more).
  int64_t next = 0;
};

// Which models modelSummaries() returns: ids above after_id, ascending, at most `limit`.
struct ModelQuery {
  int64_t after_id = 0;
  size_t limit = 100;
  std::string session;          // only models observed in this session; empty = all
  bool include_merged = false;  // also models in state "merged"
  bool include_structure = true;  // false: only models not flagged room structure
};

// What the options of every backend have (SqliteStoreOptions, PostgresStoreOptions).
struct BackendOptions {
  // Decoded scene maps kept in memory (the most recently used; each a session's TSDF and labels,
  // ~0.05-0.1 GB for a room at 2 cm). Older ones are decoded again from the database when needed.
  int max_cached_scenes = 8;
  BlobOptions blobs;  // compression of new blobs
};

// For the options' validate(): INVALID_ARGUMENT "storage.<name> must be in [min, max], got
// <value>" unless min <= value <= max.
Status checkOptionRange(std::string_view name, int64_t value, int64_t min, int64_t max);

// Everything the server asks of its database. Every mutation is one transaction; every read of
// several rows sees one snapshot. Thread-safe.
class Store : public database::ModelStore {
 public:
  ~Store() override = default;

  // What the store is, for logs and messages (SqliteStore: its file's path).
  virtual std::string describe() const = 0;
  // Bytes the database takes on disk now (SqliteStore: the file, its -wal and its -shm).
  virtual int64_t diskBytes() const = 0;
  // Whether several servers may share the database (PostgresStore; a SqliteStore's file is
  // locked by one). Servers then publish their live maps for each other.
  virtual bool sharedByServers() const { return false; }

  // The merge records whose target is model `target`, oldest first.
  virtual StatusOr<std::vector<database::MergeRecord>> mergeRecordsInto(int64_t target) const = 0;

  // The live map of an open session, saved now and then so that a crash loses only what came
  // after (replacing the earlier save). It is not the session's scene map: scene() does not see
  // it, and finishSession(kEnded) deletes it.
  virtual Status putSavedMap(const std::string& session, int64_t frames,
                             const tsdf::TsdfLayer& map, const gsm::LabelBlocks& labels) = 0;
  // The saved map of `session` brought from `base` (the map and labels of the last successful
  // putSavedMap or updateSavedMap of it) to `map` and `labels`: only the blocks that differ are
  // written (a TSDF block differs when it is not the base's block: snapshots share unchanged
  // blocks; a label block when its labels do). FAILED_PRECONDITION when no saved map of that grid
  // is stored (then putSavedMap). The default writes the whole map (putSavedMap).
  virtual Status updateSavedMap(const std::string& session, int64_t frames,
                                const tsdf::TsdfLayer& map, const gsm::LabelBlocks& labels,
                                const tsdf::TsdfLayer& base_map,
                                const gsm::LabelBlocks& base_labels);
  virtual StatusOr<SavedMap> savedMap(const std::string& session) const = 0;
  // The frame count of the session's saved map without reading it; −1 when none is saved.
  virtual StatusOr<int64_t> savedMapFrames(const std::string& session) const = 0;
  virtual Status dropSavedMap(const std::string& session) = 0;

  // Model rows without blobs (see ModelQuery), one snapshot.
  virtual StatusOr<std::vector<ModelSummary>> modelSummaries(const ModelQuery& query) const = 0;
  virtual StatusOr<ModelFate> modelFate(int64_t id) const = 0;
  // The id of a stored raw segment (NOT_FOUND when none has that key).
  virtual StatusOr<int64_t> rawSegmentId(const database::SegmentKey& key) const = 0;
  // Every raw segment's key, in the order the rows were created (ascending id). A re-extraction
  // updates its row in place and keeps its place.
  virtual StatusOr<std::vector<database::SegmentKey>> rawSegmentKeys() const = 0;

  // Sessions. beginSession creates the session (ALREADY_EXISTS when the name is taken);
  // a session row is also created implicitly, state open, by the first data stored for it.
  virtual StatusOr<SessionInfo> beginSession(const SessionInfo& info) = 0;
  virtual Status finishSession(const std::string& name, SessionState state, int64_t frames) = 0;
  // Stores a session's counters (SessionInfo::counters_json); NOT_FOUND: no such session.
  virtual Status storeSessionCounters(const std::string& name, const std::string& counters_json) = 0;
  virtual StatusOr<std::vector<SessionInfo>> sessions() const = 0;
  // Frees the name of session `name` (a replaced session, or one that never received a frame):
  // its saved map is dropped; then its row is deleted when nothing refers to it (no raw segment,
  // scene or observation), else it is renamed `renamed_to` and marked interrupted, a record of
  // what was withdrawn. Returns true when the row was deleted. NOT_FOUND: no session `name`;
  // ALREADY_EXISTS: `renamed_to` is taken.
  virtual StatusOr<bool> retireSession(const std::string& name, const std::string& renamed_to) = 0;

  // Session leases (several servers on one database): the server streaming or ending a session
  // holds its lease, renewed by heartbeats; a lease not renewed within its time to live expires,
  // and another server may then take the session over. acquireLease grants `owner` the lease of
  // `session` for `ttl` when no one holds it, it expired, or `owner` holds it already, and
  // returns the holder after the call (`owner` when granted). A lease may come before its
  // session's row (a server leases a name before it creates the session).
  virtual StatusOr<std::string> acquireLease(const std::string& session, const std::string& owner,
                                             std::chrono::milliseconds ttl) = 0;
  // Renews every lease `owner` holds that has not expired, for `ttl`; returns those sessions
  // (a session missing from the answer is no longer this owner's: it must stop writing it).
  virtual StatusOr<std::vector<std::string>> renewLeases(const std::string& owner,
                                                         std::chrono::milliseconds ttl) = 0;
  // Gives up `owner`'s lease of `session` (nothing when it does not hold it).
  virtual Status releaseLease(const std::string& session, const std::string& owner) = 0;
  // Whether a holder other than `owner` holds a lease that has not expired: another server
  // streams or ends a session on this database now.
  virtual StatusOr<bool> othersHoldLeases(const std::string& owner) const = 0;

  // The engine's integrity check plus every blob's checks.
  virtual StatusOr<CheckReport> check() const = 0;
  virtual StatusOr<StoreStats> stats() const = 0;
  // Makes everything committed durable in the database proper (clean shutdown; SqliteStore:
  // copies the WAL into the file and truncates it).
  virtual Status checkpoint() = 0;
  // An online backup: a consistent copy of the database in a new file at `path`, while writers
  // carry on. `path` is whole or absent and never replaced: an existing one is ALREADY_EXISTS.
  virtual StatusOr<BackupReport> backupTo(const std::string& path) const = 0;
};

}  // namespace objdb::storage
