// PostgresStore's sessions: created explicitly (beginSession) or by the first data stored for
// them, finished as ended or interrupted, listed.
#include "absl/strings/str_format.h"
#include "storage/postgres/postgres_internal.h"

namespace objdb::storage {

using pg::Params;
using pg::Result;

StatusOr<SessionInfo> PostgresStore::beginSession(const SessionInfo& info) {
  if (info.name.empty()) return absl::InvalidArgumentError("session name is empty");
  int64_t id = 0;
  const Status status = impl_->write(
      absl::StrFormat("beginning session %s", info.name), [&](const pg::Connection& c) -> Status {
        Params p;
        p.text(info.name).text(info.intrinsics_json).text(info.params_json).text(info.client_info);
        auto r = c.exec(absl::StrFormat("INSERT INTO sessions(name, intrinsics, params, "
                                        "started_at, state, client) VALUES ($1, $2, $3, %s, "
                                        "'open', $4) RETURNING id",
                                        pg::kNow),
                        p, "creating the session row");
        if (absl::IsAlreadyExists(r.status())) {
          return absl::AlreadyExistsError(absl::StrFormat("session %s already exists", info.name));
        }
        OBJDB_RETURN_IF_ERROR(r.status());
        id = r->integer(0, 0);
        return absl::OkStatus();
      });
  OBJDB_RETURN_IF_ERROR(status);
  SessionInfo out = info;
  out.id = id;
  out.state = SessionState::kOpen;
  return out;
}

Status PostgresStore::finishSession(const std::string& name, SessionState state, int64_t frames) {
  return impl_->write(
      absl::StrFormat("finishing session %s", name), [&](const pg::Connection& c) -> Status {
        Params p;
        p.text(sessionStateName(state)).add(frames).text(name);
        OBJDB_ASSIGN_OR_RETURN(
            Result r, c.exec(absl::StrFormat("UPDATE sessions SET state = $1, frames = $2, "
                                             "ended_at = %s WHERE name = $3",
                                             pg::kNow),
                             p, "updating the session row"));
        if (r.affected() == 0) return absl::NotFoundError(absl::StrFormat("no session %s", name));
        // Its scene map is stored: the saved live map has served its purpose.
        if (state == SessionState::kEnded) return pgstore::deleteSavedMap(c, name);
        return absl::OkStatus();
      });
}

Status PostgresStore::storeSessionCounters(const std::string& name,
                                           const std::string& counters_json) {
  return impl_->write(
      absl::StrFormat("storing the counters of session %s", name),
      [&](const pg::Connection& c) -> Status {
        Params p;
        p.text(counters_json).text(name);
        OBJDB_ASSIGN_OR_RETURN(Result r, c.exec("UPDATE sessions SET counters = $1 WHERE name = $2",
                                                p, "updating the session row"));
        if (r.affected() == 0) return absl::NotFoundError(absl::StrFormat("no session %s", name));
        return absl::OkStatus();
      });
}

StatusOr<bool> PostgresStore::retireSession(const std::string& name,
                                           const std::string& renamed_to) {
  bool deleted = false;
  const Status status = impl_->write(
      absl::StrFormat("retiring session %s", name), [&](const pg::Connection& c) -> Status {
        OBJDB_RETURN_IF_ERROR(pgstore::deleteSavedMap(c, name));
        Params by_name;
        by_name.text(name);
        OBJDB_ASSIGN_OR_RETURN(
            Result referred,
            c.exec(absl::StrFormat("SELECT %s FROM sessions s WHERE s.name = $1 FOR UPDATE",
                                   kSessionReferred),
                   by_name, "reading what refers to the session"));
        if (referred.rows() == 0) return absl::NotFoundError(absl::StrFormat("no session %s", name));
        deleted = referred.integer(0, 0) == 0;
        if (deleted) {
          return c.exec("DELETE FROM sessions WHERE name = $1", by_name, "deleting the session row")
              .status();
        }
        Params renamed;
        renamed.text(renamed_to).text(name);
        auto r = c.exec(absl::StrFormat("UPDATE sessions SET name = $1, state = 'interrupted', "
                                        "ended_at = COALESCE(ended_at, %s) WHERE name = $2",
                                        pg::kNow),
                        renamed, "renaming the session row");
        if (absl::IsAlreadyExists(r.status())) {
          return absl::AlreadyExistsError(absl::StrFormat("session %s already exists", renamed_to));
        }
        return r.status();
      });
  OBJDB_RETURN_IF_ERROR(status);
  return deleted;
}

StatusOr<std::vector<SessionInfo>> PostgresStore::sessions() const {
  std::vector<SessionInfo> out;
  OBJDB_RETURN_IF_ERROR(impl_->read("listing sessions", [&](const pg::Connection& c) -> Status {
    out.clear();
    OBJDB_ASSIGN_OR_RETURN(
        Result r, c.exec(absl::StrFormat("SELECT %s FROM sessions ORDER BY id", kSessionColumns),
                         "listing sessions"));
    for (int row = 0; row < r.rows(); ++row) out.push_back(readSession(pgstore::ResultRow(r, row)));
    return absl::OkStatus();
  }));
  return out;
}

}  // namespace objdb::storage
