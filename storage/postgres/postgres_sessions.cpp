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
        p.text(info.name).text(info.intrinsics_json).text(info.params_json);
        auto r = c.exec(absl::StrFormat("INSERT INTO sessions(name, intrinsics, params, "
                                        "started_at, state) VALUES ($1, $2, $3, %s, 'open') "
                                        "RETURNING id",
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
