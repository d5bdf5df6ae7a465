// PostgresStore with several servers on one database: session leases (table session_leases,
// expiring by the database's clock) and the writer lock of the object database (an advisory lock
// held on a connection of its own, so that the database releases it when that connection or the
// process holding it dies).
#include "absl/strings/str_format.h"
#include "storage/postgres/postgres_internal.h"

namespace objdb::storage {

using pg::Params;
using pg::Result;

namespace {

// The advisory lock key of the writer lock ("OBWL"; the schema lock is another).
constexpr int64_t kWriterLock = 0x4F42574C;

double seconds(std::chrono::milliseconds ttl) { return double(ttl.count()) / 1000.0; }

class PgWriterLock final : public database::WriterLock {
 public:
  PgWriterLock(PostgresStore::Impl* impl, std::unique_lock<std::mutex> held)
      : impl_(impl), held_(std::move(held)) {}
  ~PgWriterLock() override {
    Params key;
    key.add(kWriterLock);
    auto unlocked = impl_->writer->exec("SELECT pg_advisory_unlock($1)", key, "unlocking");
    // A lock that could not be given back goes with its connection.
    if (!unlocked.ok() || !unlocked->boolean(0, 0)) impl_->writer.reset();
  }

 private:
  PostgresStore::Impl* impl_;
  std::unique_lock<std::mutex> held_;
};

}  // namespace

StatusOr<std::unique_ptr<database::WriterLock>> PostgresStore::lockWriter() {
  std::unique_lock held(impl_->writer_mutex);
  const std::string context = "taking the object database's writer lock";
  if (impl_->writer && impl_->writer->broken()) impl_->writer.reset();
  if (!impl_->writer) {
    OBJDB_ASSIGN_OR_RETURN(pg::Connection c,
                           pg::Connection::open(impl_->uri, impl_->pool.describe(),
                                                impl_->options.connect_timeout_s));
    impl_->writer.emplace(std::move(c));
  }
  Params key;
  key.add(kWriterLock);
  auto locked = impl_->writer->exec("SELECT pg_advisory_lock($1)", key, context);
  if (!locked.ok()) {
    impl_->writer.reset();
    return annotate(locked.status(), context);
  }
  return std::unique_ptr<database::WriterLock>(
      std::make_unique<PgWriterLock>(impl_.get(), std::move(held)));
}

StatusOr<std::string> PostgresStore::acquireLease(const std::string& session,
                                                  const std::string& owner,
                                                  std::chrono::milliseconds ttl) {
  if (owner.empty()) return absl::InvalidArgumentError("lease owner is empty");
  std::string holder;
  const std::string context = absl::StrFormat("taking the lease of session %s", session);
  OBJDB_RETURN_IF_ERROR(impl_->write(context, [&](const pg::Connection& c) -> Status {
    Params p;
    p.text(session).text(owner).add(seconds(ttl));
    OBJDB_ASSIGN_OR_RETURN(
        Result taken,
        c.exec("INSERT INTO session_leases(session, owner, expires_at) VALUES ($1, $2, "
               "now() + $3 * interval '1 second') ON CONFLICT (session) DO UPDATE SET "
               "owner = EXCLUDED.owner, expires_at = EXCLUDED.expires_at WHERE "
               "session_leases.owner = EXCLUDED.owner OR session_leases.expires_at <= now() "
               "RETURNING owner",
               p, context));
    if (taken.rows() == 1) {
      holder = taken.text(0, 0);
      return absl::OkStatus();
    }
    // Not granted: the conflicting row is locked by the INSERT, so it is still there.
    Params name;
    name.text(session);
    OBJDB_ASSIGN_OR_RETURN(Result held, c.exec("SELECT owner FROM session_leases WHERE "
                                               "session = $1",
                                               name, context));
    holder = held.rows() == 1 ? held.text(0, 0) : std::string();
    return absl::OkStatus();
  }));
  return holder;
}

StatusOr<std::vector<std::string>> PostgresStore::renewLeases(const std::string& owner,
                                                              std::chrono::milliseconds ttl) {
  std::vector<std::string> held;
  OBJDB_RETURN_IF_ERROR(impl_->write("renewing session leases", [&](const pg::Connection& c)
                                                                     -> Status {
    held.clear();
    Params p;
    p.text(owner).add(seconds(ttl));
    OBJDB_ASSIGN_OR_RETURN(
        Result r, c.exec("UPDATE session_leases SET expires_at = now() + $2 * interval "
                         "'1 second' WHERE owner = $1 AND expires_at > now() RETURNING session",
                         p, "renewing session leases"));
    for (int row = 0; row < r.rows(); ++row) held.push_back(r.text(row, 0));
    return absl::OkStatus();
  }));
  return held;
}

Status PostgresStore::releaseLease(const std::string& session, const std::string& owner) {
  const std::string context = absl::StrFormat("giving up the lease of session %s", session);
  return impl_->write(context, [&](const pg::Connection& c) {
    Params p;
    p.text(session).text(owner);
    return c.exec("DELETE FROM session_leases WHERE session = $1 AND owner = $2",
                  p, context)
        .status();
  });
}

StatusOr<bool> PostgresStore::othersHoldLeases(const std::string& owner) const {
  bool others = false;
  OBJDB_RETURN_IF_ERROR(impl_->read("reading the session leases", [&](const pg::Connection& c)
                                                                        -> Status {
    Params p;
    p.text(owner);
    OBJDB_ASSIGN_OR_RETURN(
        Result r, c.exec("SELECT EXISTS (SELECT 1 FROM session_leases WHERE owner <> $1 AND "
                         "expires_at > now())",
                         p, "reading the session leases"));
    others = r.rows() == 1 && r.boolean(0, 0);
    return absl::OkStatus();
  }));
  return others;
}

}  // namespace objdb::storage
