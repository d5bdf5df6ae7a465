// ObjectDatabase on a store with several writers (ModelStore::lockWriter: several servers on one
// PostgreSQL database). Each insert and withdrawal runs under the store's writer lock, so the
// writers' changes form one sequence, Algorithm 1's order; before it matches, the database
// applies the changes the others made since it last held the lock (their models' prefilter
// entries and segments), so that it matches against every committed model, as one writer would.
#include <algorithm>
#include <chrono>
#include <iterator>

#include "absl/strings/str_format.h"
#include "core/common/logging.h"
#include "core/common/transform.h"
#include "core/database/object_database.h"

namespace objdb::database {
namespace {

double msSince(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t).count();
}

}  // namespace

StatusOr<InsertReport> ObjectDatabase::insertSegment(const std::string& session,
                                                     const gsm::RawSegment& segment,
                                                     const LiveScenes& live) {
  const auto start = std::chrono::steady_clock::now();
  if (session.empty()) return absl::InvalidArgumentError("insert: the session name is empty");
  OBJDB_RETURN_IF_ERROR(validateTransform(segment.T_world_segment, "raw segment pose"));
  if (segment.label_voxels.empty()) {
    return absl::InvalidArgumentError(
        absl::StrFormat("insert: raw segment %s/%d has no voxels", session, segment.label));
  }
  // The segment's own model needs no stored one: built before the lock, in parallel with the
  // other writers' inserts.
  Prepared prepared = prepareInsert(session, segment, live);
  const double prepare_ms = msSince(start);
  const auto wait_start = std::chrono::steady_clock::now();
  OBJDB_ASSIGN_OR_RETURN(const std::unique_ptr<WriterLock> writer, beginWrite());
  const double wait_ms = msSince(wait_start);
  auto report = insertLocked(session, segment, live, std::move(prepared));
  endWrite(writer.get());
  if (report.ok()) {
    report->timings.writer_wait_ms = writer == nullptr ? 0.0 : wait_ms;
    report->timings.total_ms = prepare_ms + report->timings.writer_hold_ms;
  }
  return report;
}

StatusOr<ObjectDatabase::Withdrawal> ObjectDatabase::withdrawSegment(const std::string& session,
                                                                     gsm::Label label) {
  OBJDB_ASSIGN_OR_RETURN(const std::unique_ptr<WriterLock> writer, beginWrite());
  auto withdrawn = withdrawLocked(session, label);
  endWrite(writer.get());
  return withdrawn;
}

StatusOr<std::unique_ptr<WriterLock>> ObjectDatabase::beginWrite() {
  OBJDB_ASSIGN_OR_RETURN(std::unique_ptr<WriterLock> writer, store_->lockWriter());
  if (writer == nullptr) return writer;  // the store's only writer: nothing to catch up on
  OBJDB_ASSIGN_OR_RETURN(const ModelChanges changes, store_->modelChangesSince(applied_seq_));
  applyChanges(changes);
  return writer;
}

void ObjectDatabase::endWrite(const WriterLock* writer) {
  if (writer == nullptr) return;
  // Under the lock the changes since the catch-up are this database's own, applied as made.
  // If the sequence cannot be read, the next catch-up applies them once more (harmless).
  if (auto seq = store_->modelChangeSeq(); seq.ok()) applied_seq_ = *seq;
}

void ObjectDatabase::applyChanges(const ModelChanges& changes) {
  if (changes.entries.empty() && changes.retired.empty()) {
    applied_seq_ = std::max(applied_seq_, changes.seq);
    return;
  }
  auto forget = [&](int64_t id) {
    for (auto it = segment_model_.begin(); it != segment_model_.end();) {
      it = it->second == id ? segment_model_.erase(it) : std::next(it);
    }
  };
  for (const int64_t id : changes.retired) {
    forget(id);
    changed(id, std::nullopt);
  }
  for (const MatchEntry& e : changes.entries) {
    forget(e.id);
    for (const auto& key : e.segments) segment_model_[key] = e.id;
    changed(e.id, e);
  }
  for (const auto& skipped : changes.skipped) {
    logger("database")->error("object database: a model another writer changed is unreadable "
                              "and left out: {}",
                              std::string(skipped.message()));
  }
  logger("database")->debug("object database: caught up with changes {}..{} of other writers: "
                            "{} models changed, {} retired",
                            applied_seq_ + 1, changes.seq, changes.entries.size(),
                            changes.retired.size());
  applied_seq_ = changes.seq;
}

}  // namespace objdb::database
