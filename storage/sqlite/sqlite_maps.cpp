// SqliteStore's maps: a session's scene map and its saved live map, one row per TSDF block and
// per label block, and the cache of decoded scene maps.
#include <list>
#include <optional>
#include <utility>

#include "absl/strings/str_format.h"
#include "storage/sqlite/sqlite_store.h"
#include "storage/row_codec.h"
#include "storage/sqlite/sqlite_store_internal.h"

namespace objdb::storage {

using internal::kNow;

Status SqliteStore::writeMap(const MapTables& tables, const std::string& session,
                             const tsdf::TsdfLayer& scene, const gsm::LabelBlocks* labels,
                             int64_t frames) {
  OBJDB_ASSIGN_OR_RETURN(
      const EncodedMap encoded,
      encodeMap(absl::StrFormat("%s of session %s", tables.what, session), scene, labels,
                options_.blobs));
  OBJDB_ASSIGN_OR_RETURN(const std::unique_lock<std::mutex> held, holdWriter());
  OBJDB_ASSIGN_OR_RETURN(Transaction txn, Transaction::begin(*writer_, Transaction::Kind::kWrite));
  OBJDB_ASSIGN_OR_RETURN(const int64_t sid, sessionIdForWrite(session));
  OBJDB_ASSIGN_OR_RETURN(
      Statement map, Statement::prepare(*writer_,
                                        "INSERT INTO %s(session_id, voxel_size, voxels_per_side, "
                                        "blocks, updated_at) VALUES (?, ?, ?, ?, %s) "
                                        "ON CONFLICT(session_id) DO UPDATE "
                                        "SET voxel_size = excluded.voxel_size, "
                                        "voxels_per_side = excluded.voxels_per_side, "
                                        "blocks = excluded.blocks, "
                                        "updated_at = excluded.updated_at",
                                        tables.maps, kNow));
  map.bind(1, sid).bind(2, encoded.voxel_size).bind(3, encoded.voxels_per_side);
  OBJDB_RETURN_IF_ERROR(map.bind(4, int64_t(encoded.tsdf.size())).run());
  if (tables.has_frames) {
    OBJDB_ASSIGN_OR_RETURN(
        Statement count,
        Statement::prepare(*writer_, "UPDATE %s SET frames = ? WHERE session_id = ?", tables.maps));
    OBJDB_RETURN_IF_ERROR(count.bind(1, frames).bind(2, sid).run());
  }
  // A block table's rows of this session replaced by `rows` (TSDF or label blocks).
  auto replaceBlocks = [&](const char* table, const char* column,
                           const std::vector<EncodedBlock>& rows) -> Status {
    OBJDB_ASSIGN_OR_RETURN(
        Statement del, Statement::prepare(*writer_, "DELETE FROM %s WHERE session_id = ?", table));
    OBJDB_RETURN_IF_ERROR(del.bind(1, sid).run());
    OBJDB_ASSIGN_OR_RETURN(Statement insert,
                           Statement::prepare(*writer_,
                                              "INSERT INTO %s(session_id, bx, by, bz, %s) "
                                              "VALUES (?, ?, ?, ?, ?)",
                                              table, column));
    for (const auto& b : rows) {
      OBJDB_RETURN_IF_ERROR(insert.reset());
      insert.bind(1, sid).bind(2, int64_t(b.index.x())).bind(3, int64_t(b.index.y()));
      OBJDB_RETURN_IF_ERROR(insert.bind(4, int64_t(b.index.z())).bindBlob(5, b.blob).run());
    }
    return absl::OkStatus();
  };
  OBJDB_RETURN_IF_ERROR(replaceBlocks(tables.blocks, "tsdf", encoded.tsdf));
  OBJDB_RETURN_IF_ERROR(replaceBlocks(tables.label_blocks, "labels", encoded.labels));
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
  scene_cache_.putScene(session, std::move(scene));
  scene_cache_.putLabels(session, std::move(labels));
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
  OBJDB_ASSIGN_OR_RETURN(Statement b,
                         Statement::prepare(connection,
                                            "SELECT l.rowid, l.bx, l.by, l.bz, l.labels, "
                                            "m.voxels_per_side FROM %s l JOIN %s m ON m.session_id "
                                            "= l.session_id JOIN sessions s ON s.id = l.session_id "
                                            "WHERE s.name = ?",
                                            tables.label_blocks, tables.maps));
  b.bind(1, session);
  auto labels = std::make_shared<gsm::LabelBlocks>();
  while (true) {
    OBJDB_ASSIGN_OR_RETURN(const bool row, b.step());
    if (!row) break;
    const tsdf::BlockIndex index(int(b.columnInt(1)), int(b.columnInt(2)), int(b.columnInt(3)));
    OBJDB_ASSIGN_OR_RETURN(
        std::vector<uint32_t> decoded,
        decodeMapLabels(b.columnBlob(4), b.columnInt(5),
                        absl::StrFormat("%s labels of session %s, block (%d, %d, %d) (%s row %d)",
                                        tables.what, session, index.x(), index.y(), index.z(),
                                        tables.label_blocks, b.columnInt(0))));
    labels->emplace(index, std::move(decoded));
  }
  std::shared_ptr<const gsm::LabelBlocks> out;
  if (!labels->empty()) out = std::move(labels);
  return out;
}

StatusOr<std::shared_ptr<const tsdf::TsdfLayer>> SqliteStore::readMapTsdf(
    const Connection& connection, const MapTables& tables, const std::string& session,
    int64_t* frames) const {
  OBJDB_ASSIGN_OR_RETURN(Statement m,
                         Statement::prepare(connection,
                                            "SELECT m.session_id, m.voxel_size, m.voxels_per_side, "
                                            "%s FROM %s m JOIN sessions s ON s.id = "
                                            "m.session_id WHERE s.name = ?",
                                            tables.has_frames ? "m.frames" : "0", tables.maps));
  m.bind(1, session);
  OBJDB_ASSIGN_OR_RETURN(const bool found, m.step());
  if (!found) return std::shared_ptr<const tsdf::TsdfLayer>();
  const int64_t sid = m.columnInt(0);
  const int vps = int(m.columnInt(2));
  if (frames != nullptr) *frames = m.columnInt(3);
  auto layer = emptyMap(absl::StrFormat("%s of session %s", tables.what, session),
                        m.columnDouble(1), vps);
  if (!layer.ok()) return layer.status();
  OBJDB_ASSIGN_OR_RETURN(Statement b, Statement::prepare(connection,
                                                         "SELECT rowid, bx, by, bz, tsdf FROM %s "
                                                         "WHERE session_id = ?",
                                                         tables.blocks));
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
  if (auto cached = scene_cache_.labels(session)) return *cached;
  OBJDB_ASSIGN_OR_RETURN(ReaderLease lease, reader());
  OBJDB_ASSIGN_OR_RETURN(std::shared_ptr<const gsm::LabelBlocks> out,
                         readMapLabels(*lease, kSceneTables, session));
  scene_cache_.putLabels(session, out);
  return out;
}

StatusOr<std::shared_ptr<const tsdf::TsdfLayer>> SqliteStore::scene(
    const std::string& session) const {
  if (auto cached = scene_cache_.scene(session)) return *cached;
  OBJDB_ASSIGN_OR_RETURN(ReaderLease lease, reader());
  OBJDB_ASSIGN_OR_RETURN(Transaction snapshot, Transaction::begin(*lease, Transaction::Kind::kRead));
  OBJDB_ASSIGN_OR_RETURN(std::shared_ptr<const tsdf::TsdfLayer> shared,
                         readMapTsdf(*lease, kSceneTables, session, nullptr));
  OBJDB_RETURN_IF_ERROR(snapshot.commit());
  if (shared == nullptr) return shared;  // no scene stored (not cached: it may come)
  scene_cache_.putScene(session, shared);
  return shared;
}

Status SqliteStore::deleteSavedMap(const std::string& session) {
  for (const char* table : {kSavedTables.label_blocks, kSavedTables.blocks, kSavedTables.maps}) {
    OBJDB_ASSIGN_OR_RETURN(Statement del,
                           Statement::prepare(*writer_,
                                              "DELETE FROM %s WHERE session_id = "
                                              "(SELECT id FROM sessions WHERE name = ?)",
                                              table));
    OBJDB_RETURN_IF_ERROR(del.bind(1, session).run());
  }
  return absl::OkStatus();
}

Status SqliteStore::dropSavedMap(const std::string& session) {
  OBJDB_ASSIGN_OR_RETURN(const std::unique_lock<std::mutex> held, holdWriter());
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

}  // namespace objdb::storage
