// SqliteStore's sessions: created explicitly (beginSession) or by the first data stored for
// them, finished as ended or interrupted, listed.
#include "absl/strings/str_format.h"
#include "storage/sqlite/sqlite_store.h"
#include "storage/sqlite/sqlite_store_internal.h"

namespace objdb::storage {

using internal::kNow;

namespace {

Status duplicateSession(const Status& status, const std::string& name) {
  if (absl::IsFailedPrecondition(status)) {
    return absl::AlreadyExistsError(absl::StrFormat("session %s already exists", name));
  }
  return status;
}

}  // namespace

StatusOr<int64_t> SqliteStore::sessionIdForWrite(const std::string& name) {
  if (name.empty()) return absl::InvalidArgumentError("session name is empty");
  OBJDB_ASSIGN_OR_RETURN(Statement insert,
                         Statement::prepare(*writer_,
                                            "INSERT INTO sessions(name, started_at, state) "
                                            "VALUES (?, %s, 'open') "
                                            "ON CONFLICT(name) DO NOTHING",
                                            kNow));
  OBJDB_RETURN_IF_ERROR(insert.bind(1, name).run());
  OBJDB_ASSIGN_OR_RETURN(Statement select,
                         Statement::prepare(*writer_, "SELECT id FROM sessions WHERE name = ?"));
  select.bind(1, name);
  OBJDB_ASSIGN_OR_RETURN(const bool row, select.step());
  if (!row) return absl::InternalError(absl::StrFormat("session %s vanished", name));
  return select.columnInt(0);
}

StatusOr<SessionInfo> SqliteStore::beginSession(const SessionInfo& info) {
  if (info.name.empty()) return absl::InvalidArgumentError("session name is empty");
  OBJDB_ASSIGN_OR_RETURN(const std::unique_lock<std::mutex> held, holdWriter());
  OBJDB_ASSIGN_OR_RETURN(Transaction txn, Transaction::begin(*writer_, Transaction::Kind::kWrite));
  OBJDB_ASSIGN_OR_RETURN(Statement s,
                         Statement::prepare(*writer_,
                                            "INSERT INTO sessions(name, intrinsics, params, "
                                            "started_at, state, client) VALUES (?, ?, ?, %s, "
                                            "'open', ?)",
                                            kNow));
  s.bind(1, info.name).bind(2, info.intrinsics_json).bind(3, info.params_json);
  s.bind(4, info.client_info);
  OBJDB_RETURN_IF_ERROR(duplicateSession(s.run(), info.name));
  const int64_t id = sqlite3_last_insert_rowid(writer_->get());
  OBJDB_RETURN_IF_ERROR(txn.commit());
  SessionInfo out = info;
  out.id = id;
  out.state = SessionState::kOpen;
  return out;
}

Status SqliteStore::finishSession(const std::string& name, SessionState state, int64_t frames) {
  OBJDB_ASSIGN_OR_RETURN(const std::unique_lock<std::mutex> held, holdWriter());
  OBJDB_ASSIGN_OR_RETURN(Statement s,
                         Statement::prepare(*writer_,
                                            "UPDATE sessions SET state = ?, frames = ?, "
                                            "ended_at = %s WHERE name = ?",
                                            kNow));
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

Status SqliteStore::storeSessionCounters(const std::string& name,
                                         const std::string& counters_json) {
  OBJDB_ASSIGN_OR_RETURN(const std::unique_lock<std::mutex> held, holdWriter());
  OBJDB_ASSIGN_OR_RETURN(Statement s, Statement::prepare(*writer_, "UPDATE sessions SET counters "
                                                                   "= ? WHERE name = ?"));
  s.bind(1, counters_json).bind(2, name);
  OBJDB_ASSIGN_OR_RETURN(Transaction txn, Transaction::begin(*writer_, Transaction::Kind::kWrite));
  OBJDB_RETURN_IF_ERROR(annotate(s.run(), absl::StrFormat("storing the counters of session %s",
                                                          name)));
  if (sqlite3_changes(writer_->get()) == 0) {
    return absl::NotFoundError(absl::StrFormat("no session %s", name));
  }
  return txn.commit();
}

StatusOr<std::vector<SessionInfo>> SqliteStore::sessions() const {
  OBJDB_ASSIGN_OR_RETURN(ReaderLease lease, reader());
  OBJDB_ASSIGN_OR_RETURN(
      Statement s,
      Statement::prepare(*lease, "SELECT %s FROM sessions ORDER BY id", kSessionColumns));
  std::vector<SessionInfo> out;
  while (true) {
    OBJDB_ASSIGN_OR_RETURN(const bool row, s.step());
    if (!row) break;
    out.push_back(readSession(internal::StatementRow(s)));
  }
  return out;
}

StatusOr<bool> SqliteStore::retireSession(const std::string& name,
                                          const std::string& renamed_to) {
  OBJDB_ASSIGN_OR_RETURN(const std::unique_lock<std::mutex> held, holdWriter());
  auto body = [&]() -> StatusOr<bool> {
    OBJDB_ASSIGN_OR_RETURN(Transaction txn,
                           Transaction::begin(*writer_, Transaction::Kind::kWrite));
    OBJDB_RETURN_IF_ERROR(deleteSavedMap(name));
    OBJDB_ASSIGN_OR_RETURN(Statement referred,
                           Statement::prepare(*writer_, "SELECT %s FROM sessions s WHERE s.name = ?",
                                              kSessionReferred));
    referred.bind(1, name);
    OBJDB_ASSIGN_OR_RETURN(const bool found, referred.step());
    if (!found) return absl::NotFoundError(absl::StrFormat("no session %s", name));
    const bool keep = referred.columnInt(0) != 0;
    OBJDB_RETURN_IF_ERROR(referred.reset());
    OBJDB_ASSIGN_OR_RETURN(
        Statement change,
        keep ? Statement::prepare(*writer_,
                                  "UPDATE sessions SET name = ?, state = 'interrupted', "
                                  "ended_at = COALESCE(ended_at, %s) WHERE name = ?",
                                  kNow)
             : Statement::prepare(*writer_, "DELETE FROM sessions WHERE name = ?"));
    if (keep) {
      change.bind(1, renamed_to).bind(2, name);
    } else {
      change.bind(1, name);
    }
    OBJDB_RETURN_IF_ERROR(keep ? duplicateSession(change.run(), renamed_to) : change.run());
    OBJDB_RETURN_IF_ERROR(txn.commit());
    return !keep;
  };
  auto retired = body();
  if (!retired.ok() && !absl::IsNotFound(retired.status()) &&
      !absl::IsAlreadyExists(retired.status())) {
    return annotate(retired.status(), absl::StrFormat("retiring session %s", name));
  }
  return retired;
}

StatusOr<std::string> SqliteStore::acquireLease(const std::string& session,
                                               const std::string& owner,
                                               std::chrono::milliseconds ttl) {
  if (owner.empty()) return absl::InvalidArgumentError("lease owner is empty");
  const auto now = std::chrono::steady_clock::now();
  std::lock_guard lock(lease_mutex_);
  Lease& held = leases_[session];
  if (held.owner.empty() || held.owner == owner || held.expires <= now) {
    held = {owner, now + ttl};
  }
  return held.owner;
}

StatusOr<std::vector<std::string>> SqliteStore::renewLeases(const std::string& owner,
                                                            std::chrono::milliseconds ttl) {
  const auto now = std::chrono::steady_clock::now();
  std::vector<std::string> held;
  std::lock_guard lock(lease_mutex_);
  for (auto& [session, lease] : leases_) {
    if (lease.owner != owner || lease.expires <= now) continue;
    lease.expires = now + ttl;
    held.push_back(session);
  }
  return held;
}

Status SqliteStore::releaseLease(const std::string& session, const std::string& owner) {
  std::lock_guard lock(lease_mutex_);
  if (const auto it = leases_.find(session); it != leases_.end() && it->second.owner == owner) {
    leases_.erase(it);
  }
  return absl::OkStatus();
}

StatusOr<bool> SqliteStore::othersHoldLeases(const std::string& owner) const {
  const auto now = std::chrono::steady_clock::now();
  std::lock_guard lock(lease_mutex_);
  for (const auto& [session, lease] : leases_) {
    if (lease.owner != owner && lease.expires > now) return true;
  }
  return false;
}

}  // namespace objdb::storage
