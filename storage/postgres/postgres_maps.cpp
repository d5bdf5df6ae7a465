// PostgresStore's maps: a session's scene map and its saved live map, one row per TSDF block and
// per label block (written in multi-row INSERTs, a few round trips per map rather than one per
// block), and the cache of decoded scene maps.
#include <algorithm>
#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "storage/postgres/postgres_internal.h"

namespace objdb::storage {

using pg::Params;
using pg::Result;

namespace {

// Block rows per INSERT statement (5 parameters each; PostgreSQL takes up to 65535).
constexpr size_t kBlocksPerInsert = 256;

// `rows` inserted into session `sid`'s rows of a block table, inside the caller's transaction;
// with `upsert` a row already there for a block is replaced.
Status insertBlocks(const pg::Connection& c, int64_t sid, const char* table, const char* column,
                    const std::vector<EncodedBlock>& rows, bool upsert) {
  for (size_t first = 0; first < rows.size(); first += kBlocksPerInsert) {
    const size_t n = std::min(kBlocksPerInsert, rows.size() - first);
    std::string values;
    Params p;
    for (size_t k = 0; k < n; ++k) {
      const EncodedBlock& b = rows[first + k];
      const size_t base = 5 * k;
      absl::StrAppend(&values, k ? ", " : "", "($", base + 1, ", $", base + 2, "::integer, $",
                      base + 3, "::integer, $", base + 4, "::integer, $", base + 5, ")");
      p.add(sid).add(int64_t(b.index.x())).add(int64_t(b.index.y())).add(int64_t(b.index.z()));
      p.bytes(b.blob);
    }
    const std::string conflict =
        upsert ? absl::StrFormat(" ON CONFLICT (session_id, bx, by, bz) DO UPDATE SET %s = "
                                 "excluded.%s",
                                 column, column)
               : std::string();
    OBJDB_RETURN_IF_ERROR(
        c.exec(absl::StrFormat("INSERT INTO %s(session_id, bx, by, bz, %s) VALUES %s%s", table,
                               column, values, conflict),
               p, absl::StrFormat("storing %s", table))
            .status());
  }
  return absl::OkStatus();
}

// Session `sid`'s rows of a block table replaced by `rows`, inside the caller's transaction.
Status replaceBlocks(const pg::Connection& c, int64_t sid, const char* table, const char* column,
                     const std::vector<EncodedBlock>& rows) {
  Params del;
  del.add(sid);
  OBJDB_RETURN_IF_ERROR(
      c.exec(absl::StrFormat("DELETE FROM %s WHERE session_id = $1", table), del,
             absl::StrFormat("clearing %s", table))
          .status());
  return insertBlocks(c, sid, table, column, rows, /*upsert=*/false);
}

// The map of `tables` for `session` rewritten from `encoded`, in one write transaction.
Status writeMap(PostgresStore::Impl& impl, const MapTables& tables, const std::string& session,
                const EncodedMap& encoded, int64_t frames, std::string_view context) {
  return impl.write(context, [&](const pg::Connection& c) -> Status {
    OBJDB_ASSIGN_OR_RETURN(const int64_t sid, pgstore::sessionIdForWrite(c, session));
    Params p;
    p.add(sid).add(encoded.voxel_size).add(encoded.voxels_per_side);
    p.add(int64_t(encoded.tsdf.size()));
    if (tables.has_frames) p.add(frames);
    OBJDB_RETURN_IF_ERROR(
        c.exec(absl::StrFormat("INSERT INTO %s(session_id, voxel_size, voxels_per_side, blocks, "
                               "%supdated_at) VALUES ($1, $2, $3, $4, %s%s) "
                               "ON CONFLICT (session_id) DO UPDATE "
                               "SET voxel_size = excluded.voxel_size, "
                               "voxels_per_side = excluded.voxels_per_side, "
                               "blocks = excluded.blocks, %supdated_at = excluded.updated_at",
                               tables.maps, tables.has_frames ? "frames, " : "",
                               tables.has_frames ? "$5, " : "", pg::kNow,
                               tables.has_frames ? "frames = excluded.frames, " : ""),
               p, absl::StrFormat("storing the %s row", tables.maps))
            .status());
    OBJDB_RETURN_IF_ERROR(replaceBlocks(c, sid, tables.blocks, "tsdf", encoded.tsdf));
    return replaceBlocks(c, sid, tables.label_blocks, "labels", encoded.labels);
  });
}

// The label blocks of a stored map (null when it has none), inside the caller's snapshot.
StatusOr<std::shared_ptr<const gsm::LabelBlocks>> readMapLabels(const pg::Connection& c,
                                                                const MapTables& tables,
                                                                const std::string& session) {
  Params p;
  p.text(session);
  OBJDB_ASSIGN_OR_RETURN(
      Result b, c.exec(absl::StrFormat("SELECT l.id, l.bx, l.by, l.bz, l.labels, "
                                       "m.voxels_per_side FROM %s l JOIN %s m ON m.session_id "
                                       "= l.session_id JOIN sessions s ON s.id = l.session_id "
                                       "WHERE s.name = $1",
                                       tables.label_blocks, tables.maps),
                       p, absl::StrFormat("reading the %s labels of session %s", tables.what,
                                          session)));
  auto labels = std::make_shared<gsm::LabelBlocks>();
  for (int row = 0; row < b.rows(); ++row) {
    const tsdf::BlockIndex index(int(b.integer(row, 1)), int(b.integer(row, 2)),
                                 int(b.integer(row, 3)));
    OBJDB_ASSIGN_OR_RETURN(
        std::vector<uint32_t> decoded,
        decodeMapLabels(b.bytes(row, 4), b.integer(row, 5),
                        absl::StrFormat("%s labels of session %s, block (%d, %d, %d) (%s row %d)",
                                        tables.what, session, index.x(), index.y(), index.z(),
                                        tables.label_blocks, b.integer(row, 0))));
    labels->emplace(index, std::move(decoded));
  }
  std::shared_ptr<const gsm::LabelBlocks> out;
  if (!labels->empty()) out = std::move(labels);
  return out;
}

// The TSDF of a stored map (null when none is stored), inside the caller's snapshot; `frames`
// gets the saved map's frame count.
StatusOr<std::shared_ptr<const tsdf::TsdfLayer>> readMapTsdf(const pg::Connection& c,
                                                             const MapTables& tables,
                                                             const std::string& session,
                                                             int64_t* frames) {
  const std::string what = absl::StrFormat("%s of session %s", tables.what, session);
  Params p;
  p.text(session);
  OBJDB_ASSIGN_OR_RETURN(
      Result m, c.exec(absl::StrFormat("SELECT m.session_id, m.voxel_size, m.voxels_per_side, %s "
                                       "FROM %s m JOIN sessions s ON s.id = m.session_id "
                                       "WHERE s.name = $1",
                                       tables.has_frames ? "m.frames" : "0::bigint", tables.maps),
                       p, absl::StrCat("reading the ", what)));
  if (m.rows() == 0) return std::shared_ptr<const tsdf::TsdfLayer>();
  const int vps = int(m.integer(0, 2));
  if (frames != nullptr) *frames = m.integer(0, 3);
  OBJDB_ASSIGN_OR_RETURN(tsdf::TsdfLayer layer, emptyMap(what, m.real(0, 1), vps));
  Params sid;
  sid.add(m.integer(0, 0));
  OBJDB_ASSIGN_OR_RETURN(
      Result b, c.exec(absl::StrFormat("SELECT id, bx, by, bz, tsdf FROM %s WHERE session_id = $1",
                                       tables.blocks),
                       sid, absl::StrCat("reading the blocks of the ", what)));
  for (int row = 0; row < b.rows(); ++row) {
    const tsdf::BlockIndex index(int(b.integer(row, 1)), int(b.integer(row, 2)),
                                 int(b.integer(row, 3)));
    tsdf::TsdfBlock& block = layer.allocateBlock(index);
    const Status decoded = decodeTsdfBlock(b.bytes(row, 4), vps, &block);
    if (!decoded.ok()) {
      return annotate(decoded, absl::StrFormat("%s, block (%d, %d, %d) (%s row %d)", what,
                                               index.x(), index.y(), index.z(), tables.blocks,
                                               b.integer(row, 0)));
    }
  }
  return std::make_shared<const tsdf::TsdfLayer>(std::move(layer));
}

}  // namespace

Status PostgresStore::putScene(const std::string& session,
                               std::shared_ptr<const tsdf::TsdfLayer> scene,
                               std::shared_ptr<const gsm::LabelBlocks> labels) {
  if (scene == nullptr) {
    return absl::InvalidArgumentError(absl::StrFormat("scene of session %s is null", session));
  }
  const std::string context = absl::StrFormat("storing the scene of session %s", session);
  auto encoded = encodeMap(absl::StrFormat("scene of session %s", session), *scene, labels.get(),
                           options_.blobs);
  if (!encoded.ok()) return annotate(encoded.status(), context);
  OBJDB_RETURN_IF_ERROR(writeMap(*impl_, kSceneTables, session, *encoded, 0, context));
  impl_->scenes.putScene(session, std::move(scene));
  impl_->scenes.putLabels(session, std::move(labels));
  return absl::OkStatus();
}

Status PostgresStore::putSavedMap(const std::string& session, int64_t frames,
                                  const tsdf::TsdfLayer& map, const gsm::LabelBlocks& labels) {
  const std::string context = absl::StrFormat("saving the live map of session %s", session);
  auto encoded =
      encodeMap(absl::StrFormat("saved map of session %s", session), map, &labels, options_.blobs);
  if (!encoded.ok()) return annotate(encoded.status(), context);
  return writeMap(*impl_, kSavedTables, session, *encoded, frames, context);
}

namespace {

// Session `sid`'s rows of a block table at `gone` deleted and `rows` written over (inserted or
// replaced), inside the caller's transaction.
Status patchBlocks(const pg::Connection& c, int64_t sid, const char* table, const char* column,
                   const std::vector<tsdf::BlockIndex>& gone, const std::vector<EncodedBlock>& rows) {
  for (size_t first = 0; first < gone.size(); first += kBlocksPerInsert) {
    const size_t n = std::min(kBlocksPerInsert, gone.size() - first);
    std::string values;
    Params p;
    p.add(sid);
    for (size_t k = 0; k < n; ++k) {
      const tsdf::BlockIndex& b = gone[first + k];
      const size_t base = 2 + 3 * k;
      absl::StrAppend(&values, k ? ", " : "", "($", base, "::integer, $", base + 1,
                      "::integer, $", base + 2, "::integer)");
      p.add(int64_t(b.x())).add(int64_t(b.y())).add(int64_t(b.z()));
    }
    OBJDB_RETURN_IF_ERROR(
        c.exec(absl::StrFormat("DELETE FROM %s WHERE session_id = $1 AND (bx, by, bz) IN (%s)",
                               table, values),
               p, absl::StrFormat("deleting rows of %s", table))
            .status());
  }
  return insertBlocks(c, sid, table, column, rows, /*upsert=*/true);
}

}  // namespace

Status PostgresStore::updateSavedMap(const std::string& session, int64_t frames,
                                     const tsdf::TsdfLayer& map, const gsm::LabelBlocks& labels,
                                     const tsdf::TsdfLayer& base_map,
                                     const gsm::LabelBlocks& base_labels) {
  const std::string context = absl::StrFormat("saving the live map of session %s", session);
  if (map.voxelSize() != base_map.voxelSize() ||
      map.voxelsPerSide() != base_map.voxelsPerSide()) {
    return absl::InvalidArgumentError(
        absl::StrFormat("%s: the base map has another grid", context));
  }
  // The difference, encoded as putSavedMap would encode those blocks.
  EncodedMap changed;
  std::vector<tsdf::BlockIndex> tsdf_gone, labels_gone;
  for (const auto& [index, block] : map.blocks()) {
    const auto it = base_map.blocks().find(index);
    if (it == base_map.blocks().end() || it->second != block) {
      changed.tsdf.push_back({index, encodeTsdfBlock(*block, options_.blobs)});
    }
  }
  for (const auto& [index, block] : base_map.blocks()) {
    if (!map.blocks().contains(index)) tsdf_gone.push_back(index);
  }
  for (const auto& [index, block] : labels) {
    const auto it = base_labels.find(index);
    if (it != base_labels.end() && it->second == block) continue;
    OBJDB_ASSIGN_OR_RETURN(EncodedBlock encoded,
                           encodeMapLabels(context, index, block, map.voxelsPerSide(),
                                           options_.blobs));
    changed.labels.push_back(std::move(encoded));
  }
  for (const auto& [index, block] : base_labels) {
    if (!labels.contains(index)) labels_gone.push_back(index);
  }
  return impl_->write(context, [&](const pg::Connection& c) -> Status {
    OBJDB_ASSIGN_OR_RETURN(const int64_t sid, pgstore::sessionIdForWrite(c, session));
    Params p;
    p.add(sid).add(frames).add(int64_t(map.numBlocks()));
    p.add(double(map.voxelSize())).add(int64_t(map.voxelsPerSide()));
    OBJDB_ASSIGN_OR_RETURN(
        Result updated,
        c.exec(absl::StrFormat("UPDATE %s SET frames = $2, blocks = $3, updated_at = %s "
                               "WHERE session_id = $1 AND voxel_size = $4 AND voxels_per_side = $5",
                               kSavedTables.maps, pg::kNow),
               p, "updating the saved map row"));
    if (updated.affected() != 1) {
      return absl::FailedPreconditionError(
          absl::StrFormat("%s: no saved map of this grid to update", context));
    }
    OBJDB_RETURN_IF_ERROR(patchBlocks(c, sid, kSavedTables.blocks, "tsdf", tsdf_gone, changed.tsdf));
    return patchBlocks(c, sid, kSavedTables.label_blocks, "labels", labels_gone, changed.labels);
  });
}

StatusOr<SavedMap> PostgresStore::savedMap(const std::string& session) const {
  SavedMap saved;
  OBJDB_RETURN_IF_ERROR(impl_->read(absl::StrFormat("reading the saved map of session %s", session),
                                    [&](const pg::Connection& c) -> Status {
                                      saved = SavedMap();
                                      OBJDB_ASSIGN_OR_RETURN(
                                          saved.map,
                                          readMapTsdf(c, kSavedTables, session, &saved.frames));
                                      OBJDB_ASSIGN_OR_RETURN(
                                          saved.labels, readMapLabels(c, kSavedTables, session));
                                      return absl::OkStatus();
                                    }));
  return saved;
}

StatusOr<std::shared_ptr<const tsdf::TsdfLayer>> PostgresStore::scene(
    const std::string& session) const {
  if (auto cached = impl_->scenes.scene(session)) return *cached;
  std::shared_ptr<const tsdf::TsdfLayer> shared;
  OBJDB_RETURN_IF_ERROR(impl_->read(absl::StrFormat("reading the scene of session %s", session),
                                    [&](const pg::Connection& c) -> Status {
                                      OBJDB_ASSIGN_OR_RETURN(
                                          shared, readMapTsdf(c, kSceneTables, session, nullptr));
                                      return absl::OkStatus();
                                    }));
  if (shared == nullptr) return shared;  // no scene stored (not cached: it may come)
  impl_->scenes.putScene(session, shared);
  return shared;
}

StatusOr<std::shared_ptr<const gsm::LabelBlocks>> PostgresStore::sceneLabels(
    const std::string& session) const {
  if (auto cached = impl_->scenes.labels(session)) return *cached;
  std::shared_ptr<const gsm::LabelBlocks> out;
  OBJDB_RETURN_IF_ERROR(
      impl_->read(absl::StrFormat("reading the scene labels of session %s", session),
                  [&](const pg::Connection& c) -> Status {
                    OBJDB_ASSIGN_OR_RETURN(out, readMapLabels(c, kSceneTables, session));
                    return absl::OkStatus();
                  }));
  // Not cached when absent: another server may store the session's scene later.
  if (out != nullptr) impl_->scenes.putLabels(session, out);
  return out;
}

namespace pgstore {

Status deleteSavedMap(const pg::Connection& c, const std::string& session) {
  // The block rows go with their map row (ON DELETE CASCADE).
  Params p;
  p.text(session);
  return c.exec("DELETE FROM saved_maps WHERE session_id = (SELECT id FROM sessions WHERE "
                "name = $1)",
                p, "deleting the saved map")
      .status();
}

}  // namespace pgstore

Status PostgresStore::dropSavedMap(const std::string& session) {
  return impl_->write(absl::StrFormat("deleting the saved map of session %s", session),
                      [&](const pg::Connection& c) { return pgstore::deleteSavedMap(c, session); });
}

StatusOr<int64_t> PostgresStore::savedMapFrames(const std::string& session) const {
  int64_t frames = -1;
  OBJDB_RETURN_IF_ERROR(impl_->read(
      absl::StrFormat("reading the saved map of session %s", session),
      [&](const pg::Connection& c) -> Status {
        Params p;
        p.text(session);
        OBJDB_ASSIGN_OR_RETURN(Result r, c.exec("SELECT m.frames FROM saved_maps m JOIN "
                                                "sessions s ON s.id = m.session_id WHERE "
                                                "s.name = $1",
                                                p, "reading the saved map frames"));
        frames = r.rows() == 0 ? -1 : r.integer(0, 0);
        return absl::OkStatus();
      }));
  return frames;
}

}  // namespace objdb::storage
