// SqliteStore's object models: a model's row (its columns and blobs) and its observations,
// written in the caller's transaction; reads of one model, of the matcher's prefilter entries and
// of the listings' summaries, each from one snapshot.
#include <algorithm>
#include <map>
#include <optional>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_split.h"
#include "core/model/global_descriptor.h"
#include "storage/sqlite/sqlite_store.h"
#include "storage/row_codec.h"
#include "storage/sqlite/sqlite_store_internal.h"

namespace objdb::storage {

using internal::kNow;

namespace {

// bindModel binds kModelColumns (row_codec.h) in their order to parameters 1..N.

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
  if (e.global_descriptor.empty()) {
    s->bindNull(22);
  } else {
    s->bindBlob(22, e.global_descriptor);
  }
}

}  // namespace

StatusOr<int64_t> SqliteStore::addModel(model::ObjectModel model) {
  const EncodedModel e = encodeModel(model, options_.blobs);
  OBJDB_ASSIGN_OR_RETURN(const std::unique_lock<std::mutex> held, holdWriter());
  auto body = [&]() -> StatusOr<int64_t> {
    OBJDB_ASSIGN_OR_RETURN(Transaction txn,
                           Transaction::begin(*writer_, Transaction::Kind::kWrite));
    std::string placeholders;
    for (int i = 0; i < kNumModelColumns; ++i) placeholders += "?, ";
    OBJDB_ASSIGN_OR_RETURN(
        Statement s, Statement::prepare(*writer_,
                                        "INSERT INTO models(%s, state, created_at, updated_at) "
                                        "VALUES (%s'active', %s, %s)",
                                        kModelColumns, placeholders, kNow, kNow));
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
  OBJDB_ASSIGN_OR_RETURN(Statement s, Statement::prepare(*writer_,
                                                         "UPDATE models SET %supdated_at = %s "
                                                         "WHERE id = ? AND state = 'active'",
                                                         assignments, kNow));
  bindModel(&s, e);
  s.bind(kNumModelColumns + 1, id);
  OBJDB_RETURN_IF_ERROR(s.run());
  if (sqlite3_changes(writer_->get()) == 0) {
    return absl::NotFoundError(absl::StrFormat("no object model %d to replace", id));
  }
  OBJDB_RETURN_IF_ERROR(writeObservations(id, e, /*replace=*/true));
  if (merge == nullptr) return absl::OkStatus();
  // The same source merged into the same model again (a re-extracted segment) supersedes its
  // earlier record: each merge is in the history once, and `merges` counts merges.
  OBJDB_ASSIGN_OR_RETURN(
      Statement d,
      Statement::prepare(*writer_, "DELETE FROM merge_records WHERE target = ? AND source = ?"));
  d.bind(1, merge->target).bind(2, merge->source);
  OBJDB_RETURN_IF_ERROR(d.run());
  OBJDB_ASSIGN_OR_RETURN(Statement m,
                         Statement::prepare(*writer_,
                                            "INSERT INTO merge_records(target, source, transform, "
                                            "icp_rmse_m, tsdf_rmse_m, tsdf_overlap, "
                                            "scene_checks, created_at) VALUES "
                                            "(?, ?, ?, ?, ?, ?, ?, %s)",
                                            kNow));
  m.bind(1, merge->target).bind(2, merge->source).bindBlob(3, encodeTransform(merge->T_target_source));
  m.bind(4, merge->icp_rmse_m).bind(5, merge->tsdf_rmse_m);
  m.bind(6, int64_t(merge->tsdf_overlap)).bind(7, int64_t(merge->scene_checks));
  return m.run();
}

Status SqliteStore::replaceModel(model::ObjectModel model,
                                 const std::optional<database::MergeRecord>& merge) {
  const EncodedModel e = encodeModel(model, options_.blobs);
  OBJDB_ASSIGN_OR_RETURN(const std::unique_lock<std::mutex> held, holdWriter());
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
  OBJDB_ASSIGN_OR_RETURN(const std::unique_lock<std::mutex> held, holdWriter());
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
  OBJDB_ASSIGN_OR_RETURN(Statement s,
                         Statement::prepare(*writer_,
                                            "UPDATE models SET state = ?, merged_into = ?, "
                                            "grid = NULL, surface_voxels = NULL, cloud = NULL, "
                                            "keypoints = NULL, descriptors = NULL, global_descriptor = NULL, "
                                            "updated_at = %s "
                                            "WHERE id = ? AND state = 'active'",
                                            kNow));
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
  OBJDB_ASSIGN_OR_RETURN(const std::unique_lock<std::mutex> held, holdWriter());
  auto body = [&]() -> Status {
    OBJDB_ASSIGN_OR_RETURN(Transaction txn,
                           Transaction::begin(*writer_, Transaction::Kind::kWrite));
    // The row stays as a tombstone (ids are never reused; merge records keep their target).
    OBJDB_RETURN_IF_ERROR(retireModel(id, 0));
    return txn.commit();
  };
  return body();
}

Status SqliteStore::setSuccessor(int64_t removed, int64_t successor) {
  OBJDB_ASSIGN_OR_RETURN(const std::unique_lock<std::mutex> held, holdWriter());
  OBJDB_ASSIGN_OR_RETURN(Statement s, Statement::prepare(*writer_,
                                                         "UPDATE models SET merged_into = ? "
                                                         "WHERE id = ? AND state = 'removed'"));
  if (successor > 0) {
    s.bind(1, successor);
  } else {
    s.bindNull(1);
  }
  return s.bind(2, removed).run();
}

StatusOr<ModelFate> SqliteStore::modelFate(int64_t id) const {
  OBJDB_ASSIGN_OR_RETURN(ReaderLease lease, reader());
  OBJDB_ASSIGN_OR_RETURN(
      Statement s,
      Statement::prepare(*lease, "SELECT state, COALESCE(merged_into, 0) FROM models WHERE id = ?"));
  s.bind(1, id);
  OBJDB_ASSIGN_OR_RETURN(const bool row, s.step());
  ModelFate fate;
  if (row) {
    fate.state = s.columnText(0);
    fate.next = s.columnInt(1);
  }
  return fate;
}

StatusOr<std::shared_ptr<const model::ObjectModel>> SqliteStore::model(int64_t id) const {
  OBJDB_ASSIGN_OR_RETURN(ReaderLease lease, reader());
  OBJDB_ASSIGN_OR_RETURN(Transaction snapshot, Transaction::begin(*lease, Transaction::Kind::kRead));
  OBJDB_ASSIGN_OR_RETURN(Statement s, Statement::prepare(*lease,
                                                         "SELECT %s FROM models WHERE id = ? AND "
                                                         "state = 'active'",
                                                         kModelColumns));
  s.bind(1, id);
  OBJDB_ASSIGN_OR_RETURN(const bool row, s.step());
  if (!row) return absl::NotFoundError(absl::StrFormat("no object model %d", id));
  OBJDB_ASSIGN_OR_RETURN(model::ObjectModel m,
                         decodeModel(id, readModelColumns(internal::StatementRow(s))));
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
    OBJDB_ASSIGN_OR_RETURN(model::Observation obs,
                           decodeObservation({o.columnInt(0), o.columnText(1), o.columnInt(2),
                                              o.columnBlob(3), o.columnBlob(4)}));
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
      Statement::prepare(*lease,
                         "SELECT %s FROM models m WHERE m.id > ?1 AND %s ORDER BY m.id LIMIT ?3",
                         kModelSummaryColumns, where));
  s.bind(1, query.after_id);
  if (!query.session.empty()) s.bind(2, query.session);
  s.bind(3, int64_t(std::min<size_t>(query.limit, size_t(1) << 30)));
  std::vector<ModelSummary> out;
  while (true) {
    OBJDB_ASSIGN_OR_RETURN(const bool row, s.step());
    if (!row) break;
    out.push_back(readModelSummary(internal::StatementRow(s)));
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

StatusOr<database::MatchEntries> SqliteStore::matchEntries(bool descriptors) const {
  OBJDB_ASSIGN_OR_RETURN(ReaderLease lease, reader());
  OBJDB_ASSIGN_OR_RETURN(Transaction snapshot, Transaction::begin(*lease, Transaction::Kind::kRead));
  database::MatchEntries out;
  std::map<int64_t, size_t> slot;  // entry of each model id
  OBJDB_ASSIGN_OR_RETURN(Statement s,
                         Statement::prepare(*lease,
                                            "SELECT %s FROM models WHERE state = 'active' "
                                            "ORDER BY id",
                                            descriptors ? kMatchEntryColumns
                                                        : kMatchEntryColumnsWithoutDescriptors));
  while (true) {
    OBJDB_ASSIGN_OR_RETURN(const bool row, s.step());
    if (!row) break;
    database::MatchEntry e;
    if (Status read = readMatchEntry(internal::StatementRow(s), &e); !read.ok()) {
      out.skipped.push_back(std::move(read));
      continue;
    }
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

StatusOr<std::vector<std::vector<model::Fpfh>>> SqliteStore::descriptorsOf(
    const std::vector<int64_t>& ids) const {
  OBJDB_ASSIGN_OR_RETURN(ReaderLease lease, reader());
  OBJDB_ASSIGN_OR_RETURN(Transaction snapshot, Transaction::begin(*lease, Transaction::Kind::kRead));
  OBJDB_ASSIGN_OR_RETURN(
      Statement s, Statement::prepare(*lease, "SELECT descriptors FROM models WHERE id = ? AND "
                                              "state = 'active'"));
  std::vector<std::vector<model::Fpfh>> out;
  out.reserve(ids.size());
  for (const int64_t id : ids) {
    OBJDB_RETURN_IF_ERROR(s.reset());
    s.bind(1, id);
    OBJDB_ASSIGN_OR_RETURN(const bool row, s.step());
    if (!row) return absl::NotFoundError(absl::StrFormat("no object model %d", id));
    if (s.columnBlob(0).empty()) {
      out.emplace_back();
      continue;
    }
    auto decoded = decodeDescriptors(s.columnBlob(0));
    if (!decoded.ok()) return inRow(decoded.status(), "models", id, "descriptors");
    out.push_back(std::move(*decoded));
  }
  OBJDB_RETURN_IF_ERROR(snapshot.commit());
  return out;
}

Status SqliteStore::putGlobalDescriptors(
    const std::vector<std::pair<int64_t, std::vector<float>>>& globals) {
  if (globals.empty()) return Status();
  OBJDB_ASSIGN_OR_RETURN(const std::unique_lock<std::mutex> held, holdWriter());
  auto body = [&]() -> Status {
    OBJDB_ASSIGN_OR_RETURN(Transaction txn,
                           Transaction::begin(*writer_, Transaction::Kind::kWrite));
    OBJDB_ASSIGN_OR_RETURN(Statement s,
                           Statement::prepare(*writer_, "UPDATE models SET global_descriptor = ? "
                                                        "WHERE id = ? AND state = 'active'"));
    for (const auto& [id, values] : globals) {
      OBJDB_RETURN_IF_ERROR(s.reset());
      s.bindBlob(1, encodeGlobalDescriptor({model::kCodebookVersion, values}, options_.blobs));
      s.bind(2, id);
      OBJDB_RETURN_IF_ERROR(s.run());
    }
    return txn.commit();
  };
  return annotate(body(), absl::StrFormat("storing %d global descriptors", globals.size()));
}

}  // namespace objdb::storage
