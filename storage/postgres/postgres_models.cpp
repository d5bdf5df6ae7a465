// PostgresStore's object models: a model's row and its observations, written in one transaction
// that locks the model rows it updates (the UPDATE first, then its observations; every body may
// run again after a deadlock, so it only reads and writes rows, never state outside them); reads of one model, of the matcher's
// prefilter entries and of the listings' summaries, each from one snapshot.
#include <algorithm>
#include <map>
#include <optional>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_split.h"
#include "core/model/global_descriptor.h"
#include "storage/postgres/postgres_internal.h"

namespace objdb::storage {

using pg::Params;
using pg::Result;

namespace {

// Every write of a model row takes the next number of the change sequence (schema 2).
constexpr const char* kNextChange = "nextval('model_changes')";

// addModelColumns adds kModelColumns (row_codec.h) in their order.

void addModelColumns(Params* p, const EncodedModel& e) {
  p->add(e.planar).add(e.plane_inlier_ratio).add(e.num_points).add(e.num_keypoints);
  p->add(e.voxel_size);
  for (int k = 0; k < 3; ++k) p->add(double(e.bbox_min[k]));
  for (int k = 0; k < 3; ++k) p->add(double(e.bbox_max[k]));
  p->bytes(e.grid).bytes(e.surface_voxels).bytes(e.cloud).bytes(e.keypoints).bytes(e.descriptors);
  p->add(e.timings.cloud_ms).add(e.timings.planarity_ms).add(e.timings.keypoints_ms);
  p->add(e.timings.descriptors_ms).add(e.structure);
  if (e.global_descriptor.empty()) {
    p->null();
  } else {
    p->bytes(e.global_descriptor);
  }
}

// "$first, $first+1, ..." for `n` parameters.
std::string placeholders(int first, int n) {
  std::string out;
  for (int i = 0; i < n; ++i) absl::StrAppend(&out, i ? ", $" : "$", first + i);
  return out;
}

// Calls `add(row, slot)` for each row of `rows` whose model (the id in column `id_column`) has a
// slot in `slots`, until an error; the rows of other models are passed over.
template <typename Add>
Status forRowsOfModels(const Result& rows, int id_column, const std::map<int64_t, size_t>& slots,
                       Add add) {
  for (int row = 0; row < rows.rows(); ++row) {
    const auto it = slots.find(rows.integer(row, id_column));
    if (it != slots.end()) OBJDB_RETURN_IF_ERROR(add(row, it->second));
  }
  return absl::OkStatus();
}

// The observation rows of model `model_id` (replacing its earlier ones when `replace`), inside
// the caller's write transaction.
Status writeObservations(const pg::Connection& c, int64_t model_id, const EncodedModel& model,
                         bool replace) {
  if (replace) {
    Params del;
    del.add(model_id);
    OBJDB_RETURN_IF_ERROR(
        c.exec("DELETE FROM observations WHERE model_id = $1", del, "dropping observations")
            .status());
  }
  for (size_t k = 0; k < model.observations.size(); ++k) {
    const auto& o = model.observations[k];
    OBJDB_ASSIGN_OR_RETURN(const int64_t sid, pgstore::sessionIdForWrite(c, o.session));
    Params p;
    p.add(model_id).add(int64_t(k)).add(sid).add(o.label).bytes(o.T_world_object);
    p.bytes(o.T_object_segment);
    OBJDB_RETURN_IF_ERROR(
        c.exec("INSERT INTO observations(model_id, seq, session_id, label, raw_segment_id, "
               "t_world_object, t_object_segment) VALUES ($1, $2, $3, $4, (SELECT id FROM "
               "raw_segments WHERE session_id = $3 AND label = $4), $5, $6)",
               p, "storing an observation")
            .status());
  }
  return absl::OkStatus();
}

// Active model `id` out of the active set: state removed, or merged into `merged_into` (> 0);
// its blobs and observations dropped, its row kept. Inside the caller's write transaction.
Status retireModel(const pg::Connection& c, int64_t id, int64_t merged_into) {
  Params p;
  p.text(merged_into > 0 ? "merged" : "removed");
  if (merged_into > 0) {
    p.add(merged_into);
  } else {
    p.null();
  }
  p.add(id);
  OBJDB_ASSIGN_OR_RETURN(
      Result r, c.exec(absl::StrFormat("UPDATE models SET state = $1, merged_into = $2::bigint, "
                                       "grid = NULL, surface_voxels = NULL, cloud = NULL, "
                                       "keypoints = NULL, descriptors = NULL, global_descriptor = NULL, "
                                       "updated_at = %s, "
                                       "change_seq = %s WHERE id = $3 AND state = 'active'",
                                       pg::kNow, kNextChange),
                       p, "retiring the model"));
  if (r.affected() == 0) {
    return absl::NotFoundError(absl::StrFormat("no object model %d to %s", id,
                                               merged_into > 0 ? "merge" : "remove"));
  }
  Params del;
  del.add(id);
  return c.exec("DELETE FROM observations WHERE model_id = $1", del, "dropping observations")
      .status();
}

// Model `id`'s row and observations rewritten from `e`, with `merge` recorded when given. Inside
// the caller's write transaction.
Status rewriteModel(const pg::Connection& c, const EncodedModel& e, int64_t id,
                    const database::MergeRecord* merge) {
  std::string assignments;
  int n = 1;
  for (const absl::string_view column : absl::StrSplit(kModelColumns, ", ")) {
    absl::StrAppend(&assignments, column, " = $", n++, ", ");
  }
  Params p;
  addModelColumns(&p, e);
  p.add(id);
  OBJDB_ASSIGN_OR_RETURN(
      Result r, c.exec(absl::StrFormat("UPDATE models SET %supdated_at = %s, change_seq = %s "
                                       "WHERE id = $%d AND state = 'active'",
                                       assignments, pg::kNow, kNextChange,
                                       kNumModelColumns + 1),
                       p, "rewriting the model"));
  if (r.affected() == 0) {
    return absl::NotFoundError(absl::StrFormat("no object model %d to replace", id));
  }
  OBJDB_RETURN_IF_ERROR(writeObservations(c, id, e, /*replace=*/true));
  if (merge == nullptr) return absl::OkStatus();
  // The same source merged into the same model again (a re-extracted segment) supersedes its
  // earlier record: each merge is in the history once, and `merges` counts merges.
  Params d;
  d.add(merge->target).text(merge->source);
  OBJDB_RETURN_IF_ERROR(
      c.exec("DELETE FROM merge_records WHERE target = $1 AND source = $2", d,
             "superseding the earlier record of the merge")
          .status());
  Params m;
  m.add(merge->target).text(merge->source).bytes(encodeTransform(merge->T_target_source));
  m.add(merge->icp_rmse_m).add(merge->tsdf_rmse_m).add(int64_t(merge->tsdf_overlap));
  m.add(int64_t(merge->scene_checks));
  return c.exec(absl::StrFormat("INSERT INTO merge_records(target, source, transform, "
                                "icp_rmse_m, tsdf_rmse_m, tsdf_overlap, scene_checks, "
                                "created_at) VALUES ($1, $2, $3, $4, $5, $6, $7, %s)",
                                pg::kNow),
                m, "recording the merge")
      .status();
}

}  // namespace

StatusOr<int64_t> PostgresStore::addModel(model::ObjectModel model) {
  const EncodedModel e = encodeModel(model, options_.blobs);
  int64_t id = 0;
  const Status status = impl_->write("adding an object model", [&](const pg::Connection& c) {
    Params p;
    addModelColumns(&p, e);
    OBJDB_ASSIGN_OR_RETURN(
        Result r, c.exec(absl::StrFormat("INSERT INTO models(%s, state, created_at, updated_at, "
                                         "change_seq) VALUES (%s, 'active', %s, %s, %s) "
                                         "RETURNING id",
                                         kModelColumns, placeholders(1, kNumModelColumns),
                                         pg::kNow, pg::kNow, kNextChange),
                         p, "inserting the models row"));
    id = r.integer(0, 0);
    return writeObservations(c, id, e, /*replace=*/false);
  });
  if (!status.ok()) return annotate(status, "adding an object model");
  return id;
}

Status PostgresStore::replaceModel(model::ObjectModel model,
                                   const std::optional<database::MergeRecord>& merge) {
  const EncodedModel e = encodeModel(model, options_.blobs);
  const std::string context = absl::StrFormat("replacing object model %d", model.id);
  return annotate(impl_->write(context,
                               [&](const pg::Connection& c) {
                                 return rewriteModel(c, e, model.id, merge ? &*merge : nullptr);
                               }),
                  context);
}

Status PostgresStore::absorbModel(model::ObjectModel target, const database::MergeRecord& merge,
                                  int64_t absorbed) {
  const std::string context =
      absl::StrFormat("merging object model %d into object model %d", absorbed, target.id);
  if (absorbed == target.id) {
    return absl::InvalidArgumentError(
        absl::StrCat(context, ": a model cannot be merged into itself"));
  }
  const EncodedModel e = encodeModel(target, options_.blobs);
  return annotate(impl_->write(context,
                               [&](const pg::Connection& c) -> Status {
                                 // The absorbed row stays for lineage (state merged,
                                 // merged_into the target).
                                 OBJDB_RETURN_IF_ERROR(retireModel(c, absorbed, target.id));
                                 return rewriteModel(c, e, target.id, &merge);
                               }),
                  context);
}

Status PostgresStore::removeModel(int64_t id) {
  // The row stays as a tombstone (ids are never reused; merge records keep their target).
  return impl_->write(absl::StrFormat("removing object model %d", id),
                      [&](const pg::Connection& c) { return retireModel(c, id, 0); });
}

Status PostgresStore::setSuccessor(int64_t removed, int64_t successor) {
  return impl_->write(
      absl::StrFormat("recording where removed object model %d went", removed),
      [&](const pg::Connection& c) {
        Params p;
        if (successor > 0) {
          p.add(successor);
        } else {
          p.null();
        }
        p.add(removed);
        return c.exec("UPDATE models SET merged_into = $1::bigint WHERE id = $2 AND "
                      "state = 'removed'",
                      p, "recording the successor")
            .status();
      });
}

StatusOr<ModelFate> PostgresStore::modelFate(int64_t id) const {
  ModelFate fate;
  const std::string context = absl::StrFormat("reading the state of object model %d", id);
  OBJDB_RETURN_IF_ERROR(impl_->read(context, [&](const pg::Connection& c) -> Status {
    fate = ModelFate{};
    Params p;
    p.add(id);
    OBJDB_ASSIGN_OR_RETURN(
        Result r, c.exec("SELECT state, COALESCE(merged_into, 0) FROM models WHERE id = $1", p,
                         context));
    if (r.rows() > 0) {
      fate.state = r.text(0, 0);
      fate.next = r.integer(0, 1);
    }
    return absl::OkStatus();
  }));
  return fate;
}

StatusOr<std::shared_ptr<const model::ObjectModel>> PostgresStore::model(int64_t id) const {
  std::optional<model::ObjectModel> out;
  const std::string context = absl::StrFormat("reading object model %d", id);
  OBJDB_RETURN_IF_ERROR(impl_->read(context, [&](const pg::Connection& c) -> Status {
    out.reset();
    Params p;
    p.add(id);
    OBJDB_ASSIGN_OR_RETURN(
        Result s, c.exec(absl::StrFormat("SELECT %s FROM models WHERE id = $1 AND "
                                         "state = 'active'",
                                         kModelColumns),
                         p, context));
    if (s.rows() == 0) return absl::NotFoundError(absl::StrFormat("no object model %d", id));
    OBJDB_ASSIGN_OR_RETURN(model::ObjectModel m,
                           decodeModel(id, readModelColumns(pgstore::ResultRow(s, 0))));
    OBJDB_ASSIGN_OR_RETURN(
        Result o, c.exec("SELECT o.id, s.name, o.label, o.t_world_object, o.t_object_segment "
                         "FROM observations o JOIN sessions s ON s.id = o.session_id "
                         "WHERE o.model_id = $1 ORDER BY o.seq",
                         p, context));
    for (int row = 0; row < o.rows(); ++row) {
      OBJDB_ASSIGN_OR_RETURN(model::Observation obs,
                             decodeObservation({o.integer(row, 0), o.text(row, 1),
                                                o.integer(row, 2), o.bytes(row, 3),
                                                o.bytes(row, 4)}));
      m.observations.push_back(std::move(obs));
    }
    out = std::move(m);
    return absl::OkStatus();
  }));
  return std::shared_ptr<const model::ObjectModel>(
      std::make_shared<model::ObjectModel>(std::move(*out)));
}

StatusOr<std::vector<ModelSummary>> PostgresStore::modelSummaries(const ModelQuery& query) const {
  std::vector<ModelSummary> out;
  OBJDB_RETURN_IF_ERROR(impl_->read("listing object models", [&](const pg::Connection& c)
                                                                 -> Status {
    out.clear();
    Params p;
    p.add(query.after_id).add(int64_t(std::min<size_t>(query.limit, size_t(1) << 30)));
    std::string where =
        query.include_merged ? "m.state IN ('active', 'merged')" : "m.state = 'active'";
    if (!query.include_structure) where += " AND NOT m.structure";
    if (!query.session.empty()) {
      p.text(query.session);
      where += " AND m.id IN (SELECT o.model_id FROM observations o JOIN sessions s ON "
               "s.id = o.session_id WHERE s.name = $3)";
    }
    OBJDB_ASSIGN_OR_RETURN(
        Result s,
        c.exec(absl::StrFormat("SELECT %s FROM models m WHERE m.id > $1 AND %s ORDER BY m.id "
                               "LIMIT $2",
                               kModelSummaryColumns, where),
               p, "listing object models"));
    std::map<int64_t, size_t> slot;
    for (int row = 0; row < s.rows(); ++row) {
      out.push_back(readModelSummary(pgstore::ResultRow(s, row)));
      slot[out.back().id] = out.size() - 1;
    }
    if (out.empty()) return absl::OkStatus();
    // One round trip for the page's observations: the id range, then the page's ids.
    Params range;
    range.add(out.front().id).add(out.back().id);
    OBJDB_ASSIGN_OR_RETURN(
        Result o, c.exec("SELECT o.id, o.model_id, s.name, o.label, "
                         "COALESCE(o.raw_segment_id, 0), o.t_world_object, "
                         "COALESCE(r.parts, '') FROM observations o JOIN sessions s ON "
                         "s.id = o.session_id LEFT JOIN raw_segments r ON "
                         "r.id = o.raw_segment_id WHERE o.model_id BETWEEN $1 AND $2 "
                         "ORDER BY o.model_id, o.seq",
                         range, "listing observations"));
    return forRowsOfModels(o, 1, slot, [&](int row, size_t model) -> Status {
      auto T_wo = decodeTransform(o.bytes(row, 5));
      if (!T_wo.ok()) {
        return inRow(T_wo.status(), "observations", o.integer(row, 0), "t_world_object");
      }
      auto parts = parseParts(o.text(row, 6));
      if (!parts.ok()) return inRow(parts.status(), "raw_segments", o.integer(row, 4), "parts");
      out[model].observations.push_back({o.text(row, 2), uint32_t(o.integer(row, 3)),
                                         o.integer(row, 4), *T_wo, std::move(*parts)});
      return absl::OkStatus();
    });
  }));
  return out;
}

StatusOr<std::vector<int64_t>> PostgresStore::modelIds() const {
  std::vector<int64_t> ids;
  OBJDB_RETURN_IF_ERROR(impl_->read("listing object model ids", [&](const pg::Connection& c)
                                                                     -> Status {
    ids.clear();
    OBJDB_ASSIGN_OR_RETURN(Result r, c.exec("SELECT id FROM models WHERE state = 'active' "
                                            "ORDER BY id",
                                            "listing object model ids"));
    for (int row = 0; row < r.rows(); ++row) ids.push_back(r.integer(row, 0));
    return absl::OkStatus();
  }));
  return ids;
}

namespace {

// The prefilter entries of the active models changed after change `since` (0: every active
// model), inside the caller's read snapshot; `retired` (when given) gets the models changed
// after it that are no longer active.
Status readMatchEntries(const pg::Connection& c, int64_t since, bool descriptors,
                        database::MatchEntries* out, std::vector<int64_t>* retired) {
  Params p;
  p.add(since);
  if (retired != nullptr) {
    OBJDB_ASSIGN_OR_RETURN(Result r, c.exec("SELECT id FROM models WHERE change_seq >= $1 AND "
                                            "state <> 'active' ORDER BY id",
                                            p, "reading model changes"));
    for (int row = 0; row < r.rows(); ++row) retired->push_back(r.integer(row, 0));
  }
  OBJDB_ASSIGN_OR_RETURN(Result s,
                         c.exec(absl::StrFormat("SELECT %s FROM models WHERE state = 'active' AND "
                                                "change_seq >= $1 ORDER BY id",
                                                descriptors
                                                    ? kMatchEntryColumns
                                                    : kMatchEntryColumnsWithoutDescriptors),
                                p, "reading match entries"));
  std::map<int64_t, size_t> slot;
  for (int row = 0; row < s.rows(); ++row) {
    database::MatchEntry e;
    if (Status read = readMatchEntry(pgstore::ResultRow(s, row), &e); !read.ok()) {
      out->skipped.push_back(std::move(read));
      if (retired != nullptr) retired->push_back(e.id);  // its earlier entry is stale
      continue;
    }
    slot[e.id] = out->entries.size();
    out->entries.push_back(std::move(e));
  }
  OBJDB_ASSIGN_OR_RETURN(
      Result o, c.exec("SELECT o.model_id, s.name, o.label FROM observations o "
                       "JOIN sessions s ON s.id = o.session_id JOIN models m ON "
                       "m.id = o.model_id WHERE m.state = 'active' AND m.change_seq >= $1 "
                       "ORDER BY o.model_id, o.seq",
                       p, "reading match entries"));
  return forRowsOfModels(o, 0, slot, [&](int row, size_t entry) {
    out->entries[entry].segments.push_back({o.text(row, 1), uint32_t(o.integer(row, 2))});
    return absl::OkStatus();
  });
}

}  // namespace

StatusOr<database::MatchEntries> PostgresStore::matchEntries(bool descriptors) const {
  database::MatchEntries out;
  OBJDB_RETURN_IF_ERROR(impl_->read("reading match entries", [&](const pg::Connection& c) {
    out = {};
    return readMatchEntries(c, 0, descriptors, &out, nullptr);
  }));
  return out;
}

StatusOr<int64_t> PostgresStore::modelChangeSeq() const {
  int64_t seq = 0;
  OBJDB_RETURN_IF_ERROR(impl_->read("reading the model change sequence",
                                    [&](const pg::Connection& c) -> Status {
                                      OBJDB_ASSIGN_OR_RETURN(
                                          Result r, c.exec("SELECT COALESCE(MAX(change_seq), 0) "
                                                           "FROM models",
                                                           "reading the change sequence"));
                                      seq = r.integer(0, 0);
                                      return absl::OkStatus();
                                    }));
  return seq;
}

StatusOr<database::ModelChanges> PostgresStore::modelChangesSince(int64_t seq) const {
  database::ModelChanges out;
  OBJDB_RETURN_IF_ERROR(impl_->read("reading model changes", [&](const pg::Connection& c)
                                                                  -> Status {
    out = {};
    OBJDB_ASSIGN_OR_RETURN(Result r, c.exec("SELECT COALESCE(MAX(change_seq), 0) FROM models",
                                            "reading the change sequence"));
    out.seq = std::max(seq, r.integer(0, 0));
    if (out.seq == seq) return absl::OkStatus();
    database::MatchEntries entries;
    OBJDB_RETURN_IF_ERROR(readMatchEntries(c, seq + 1, true, &entries, &out.retired));
    out.entries = std::move(entries.entries);
    out.skipped = std::move(entries.skipped);
    return absl::OkStatus();
  }));
  return out;
}

StatusOr<std::vector<std::vector<model::Fpfh>>> PostgresStore::descriptorsOf(
    const std::vector<int64_t>& ids) const {
  std::vector<std::vector<model::Fpfh>> out;
  OBJDB_RETURN_IF_ERROR(impl_->read("reading descriptors", [&](const pg::Connection& c) -> Status {
    out.assign(ids.size(), {});
    Params p;
    p.text(absl::StrCat("{", absl::StrJoin(ids, ","), "}"));
    OBJDB_ASSIGN_OR_RETURN(Result r, c.exec("SELECT id, descriptors FROM models WHERE "
                                            "state = 'active' AND id = ANY($1::text::bigint[])",
                                            p, "reading descriptors"));
    std::map<int64_t, int> row_of;
    for (int row = 0; row < r.rows(); ++row) row_of[r.integer(row, 0)] = row;
    for (size_t i = 0; i < ids.size(); ++i) {
      const auto it = row_of.find(ids[i]);
      if (it == row_of.end()) {
        return absl::NotFoundError(absl::StrFormat("no object model %d", ids[i]));
      }
      const std::string_view blob = r.bytes(it->second, 1);
      if (blob.empty()) continue;
      auto decoded = decodeDescriptors(blob);
      if (!decoded.ok()) return inRow(decoded.status(), "models", ids[i], "descriptors");
      out[i] = std::move(*decoded);
    }
    return absl::OkStatus();
  }));
  return out;
}

Status PostgresStore::putGlobalDescriptors(
    const std::vector<std::pair<int64_t, std::vector<float>>>& globals) {
  if (globals.empty()) return absl::OkStatus();
  // Not a change of the models: the change sequence stays, other writers compute their own.
  return impl_->write(absl::StrFormat("storing %d global descriptors", globals.size()),
                      [&](const pg::Connection& c) -> Status {
                        for (const auto& [id, values] : globals) {
                          Params p;
                          p.bytes(encodeGlobalDescriptor({model::kCodebookVersion, values},
                                                         options_.blobs));
                          p.add(id);
                          OBJDB_RETURN_IF_ERROR(c.exec("UPDATE models SET global_descriptor = $1 "
                                                       "WHERE id = $2 AND state = 'active'",
                                                       p, "storing a global descriptor")
                                                    .status());
                        }
                        return absl::OkStatus();
                      });
}

}  // namespace objdb::storage
