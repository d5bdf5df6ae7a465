// PostgresStore: opening (connection, schema), raw segments and merge records.
#include "storage/postgres/postgres_store.h"

#include <regex>

#include "absl/strings/match.h"
#include "absl/strings/str_format.h"
#include "core/common/logging.h"
#include "storage/postgres/postgres_internal.h"

namespace objdb::storage {

using pg::Params;
using pg::Result;

bool isPostgresTarget(const std::string& target) {
  return absl::StartsWith(target, "postgresql://") || absl::StartsWith(target, "postgres://");
}

std::string redactPostgresUri(const std::string& uri) {
  // postgresql://user:password@host/..., the password= and sslpassword= (client key passphrase)
  // query parameters, and the same keywords in a keyword/value connection string.
  static const std::regex userinfo(R"(^(postgres(?:ql)?://[^:/?#@]*):[^@/?#]*@)");
  static const std::regex query(R"(([?&](?:ssl)?password=)[^&#]*)");
  static const std::regex keyword(R"((^|\s)((?:ssl)?password\s*=\s*)('(?:[^'\\]|\\.)*'|[^\s']\S*))");
  std::string out = std::regex_replace(uri, userinfo, "$1:***@");
  out = std::regex_replace(out, query, "$1***");
  if (out.rfind("postgres", 0) == 0) return out;
  return std::regex_replace(out, keyword, "$1$2***");
}

Status PostgresStoreOptions::validate() const {
  OBJDB_RETURN_IF_ERROR(checkOptionRange("pool_size", pool_size, 1, 256));
  OBJDB_RETURN_IF_ERROR(checkOptionRange("connect_timeout_s", connect_timeout_s, 1, 600));
  OBJDB_RETURN_IF_ERROR(
      checkOptionRange("max_transaction_retries", max_transaction_retries, 0, 1000));
  return checkOptionRange("max_cached_scenes", max_cached_scenes, 1, 1024);
}

PostgresStore::PostgresStore(std::string uri, PostgresStoreOptions options)
    : uri_(std::move(uri)), options_(std::move(options)) {}

PostgresStore::~PostgresStore() = default;

StatusOr<std::unique_ptr<PostgresStore>> PostgresStore::open(const std::string& uri,
                                                             const PostgresStoreOptions& options) {
  OBJDB_RETURN_IF_ERROR(options.validate());
  std::unique_ptr<PostgresStore> store(new PostgresStore(uri, options));
  const std::string describe = store->describe();
  store->impl_ = std::make_unique<Impl>(uri, describe, options);
  {
    OBJDB_ASSIGN_OR_RETURN(pg::ConnectionPool::Lease lease, store->impl_->pool.acquire());
    OBJDB_ASSIGN_OR_RETURN(const SchemaState schema,
                           pg::prepareSchema(*lease, describe, pg::schemaMigrations()));
    store->schema_version_ = schema.version_after;
    logger("storage")->info("opened {} (schema {}{})", describe, schema.version_after,
                            schema.created ? ", new" : "");
  }
  return store;
}

std::string PostgresStore::describe() const { return redactPostgresUri(uri_); }

int64_t PostgresStore::transactionRetries() const { return impl_->pool.retries(); }

int64_t PostgresStore::diskBytes() const {
  int64_t bytes = -1;
  const Status status = impl_->read("measuring the database", [&](const pg::Connection& c) {
    OBJDB_ASSIGN_OR_RETURN(Result r, c.exec("SELECT pg_database_size(current_database())",
                                            "measuring the database"));
    bytes = r.integer(0, 0);
    return absl::OkStatus();
  });
  return status.ok() ? bytes : -1;
}

namespace pgstore {

StatusOr<int64_t> sessionIdForWrite(const pg::Connection& c, const std::string& name) {
  if (name.empty()) return absl::InvalidArgumentError("session name is empty");
  Params p;
  p.text(name);
  OBJDB_ASSIGN_OR_RETURN(
      Result inserted,
      c.exec(absl::StrFormat("INSERT INTO sessions(name, started_at, state) VALUES ($1, %s, "
                             "'open') ON CONFLICT (name) DO NOTHING RETURNING id",
                             pg::kNow),
             p, "creating the session row"));
  if (inserted.rows() == 1) return inserted.integer(0, 0);
  OBJDB_ASSIGN_OR_RETURN(Result found, c.exec("SELECT id FROM sessions WHERE name = $1", p,
                                              "reading the session row"));
  if (found.rows() != 1) return absl::InternalError(absl::StrFormat("session %s vanished", name));
  return found.integer(0, 0);
}

}  // namespace pgstore

Status PostgresStore::putRawSegment(const database::RawSegmentRecord& segment) {
  OBJDB_ASSIGN_OR_RETURN(const EncodedRawSegment e, encodeRawSegment(segment, options_.blobs));
  const std::string context =
      absl::StrFormat("storing raw segment %s/%d", segment.key.session, segment.key.label);
  return impl_->write(context, [&](const pg::Connection& c) -> Status {
    OBJDB_ASSIGN_OR_RETURN(const int64_t sid, pgstore::sessionIdForWrite(c, segment.key.session));
    Params p;
    p.add(sid).add(int64_t(segment.key.label)).bytes(e.pose).bytes(e.grid).bytes(e.voxels);
    p.add(segment.extraction_frame).add(double(segment.observation_depth_m)).text(e.parts);
    if (e.voxel_parts) {
      p.bytes(*e.voxel_parts);
    } else {
      p.null();
    }
    return c.exec(absl::StrFormat(
                      "INSERT INTO raw_segments(session_id, label, pose, grid, voxels, "
                      "extraction_frame, observation_depth_m, parts, voxel_parts, extracted_at) "
                      "VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9::bytea, %s) "
                      "ON CONFLICT (session_id, label) DO UPDATE SET pose = excluded.pose, "
                      "grid = excluded.grid, voxels = excluded.voxels, "
                      "extraction_frame = excluded.extraction_frame, "
                      "observation_depth_m = excluded.observation_depth_m, "
                      "parts = excluded.parts, voxel_parts = excluded.voxel_parts, "
                      "extracted_at = excluded.extracted_at",
                      pg::kNow),
                  p, context)
        .status();
  });
}

StatusOr<std::shared_ptr<const database::RawSegmentRecord>> PostgresStore::rawSegment(
    const database::SegmentKey& key) const {
  std::shared_ptr<const database::RawSegmentRecord> out;
  const std::string context = absl::StrFormat("reading raw segment %s/%d", key.session, key.label);
  OBJDB_RETURN_IF_ERROR(impl_->read(context, [&](const pg::Connection& c) -> Status {
    Params p;
    p.text(key.session).add(int64_t(key.label));
    OBJDB_ASSIGN_OR_RETURN(
        Result r, c.exec(absl::StrFormat("SELECT %s FROM raw_segments r JOIN sessions s ON "
                                         "s.id = r.session_id WHERE s.name = $1 AND r.label = $2",
                                         kRawSegmentColumns),
                         p, context));
    if (r.rows() == 0) {
      return absl::NotFoundError(absl::StrFormat("no raw segment %s/%d", key.session, key.label));
    }
    OBJDB_ASSIGN_OR_RETURN(out,
                           decodeRawSegment(key, readRawSegmentColumns(pgstore::ResultRow(r, 0))));
    return absl::OkStatus();
  }));
  return out;
}

StatusOr<std::vector<float>> PostgresStore::observationDepths(
    const std::vector<database::SegmentKey>& keys) const {
  std::vector<float> depths;
  OBJDB_RETURN_IF_ERROR(
      impl_->read("reading raw segments' depths", [&](const pg::Connection& c) -> Status {
        depths.clear();
        depths.reserve(keys.size());
        for (const auto& key : keys) {
          Params p;
          p.text(key.session).add(int64_t(key.label));
          OBJDB_ASSIGN_OR_RETURN(
              Result r,
              c.exec("SELECT r.observation_depth_m FROM raw_segments r JOIN sessions s ON "
                     "s.id = r.session_id WHERE s.name = $1 AND r.label = $2",
                     p, "reading raw segments' depths"));
          if (r.rows() == 0) {
            return absl::NotFoundError(
                absl::StrFormat("no raw segment %s/%d", key.session, key.label));
          }
          depths.push_back(float(r.real(0, 0)));
        }
        return absl::OkStatus();
      }));
  return depths;
}

StatusOr<int64_t> PostgresStore::rawSegmentId(const database::SegmentKey& key) const {
  int64_t id = 0;
  const std::string context = absl::StrFormat("reading raw segment %s/%d", key.session, key.label);
  OBJDB_RETURN_IF_ERROR(impl_->read(context, [&](const pg::Connection& c) -> Status {
    Params p;
    p.text(key.session).add(int64_t(key.label));
    OBJDB_ASSIGN_OR_RETURN(Result r, c.exec("SELECT r.id FROM raw_segments r JOIN sessions s ON "
                                            "s.id = r.session_id WHERE s.name = $1 AND "
                                            "r.label = $2",
                                            p, context));
    if (r.rows() == 0) {
      return absl::NotFoundError(absl::StrFormat("no raw segment %s/%d", key.session, key.label));
    }
    id = r.integer(0, 0);
    return absl::OkStatus();
  }));
  return id;
}

StatusOr<std::vector<database::SegmentKey>> PostgresStore::rawSegmentKeys() const {
  std::vector<database::SegmentKey> keys;
  OBJDB_RETURN_IF_ERROR(impl_->read("listing raw segments", [&](const pg::Connection& c) -> Status {
    keys.clear();
    OBJDB_ASSIGN_OR_RETURN(Result r, c.exec("SELECT s.name, r.label FROM raw_segments r JOIN "
                                            "sessions s ON s.id = r.session_id ORDER BY r.id",
                                            Params(), "listing raw segments"));
    for (int row = 0; row < r.rows(); ++row) {
      keys.push_back({r.text(row, 0), uint32_t(r.integer(row, 1))});
    }
    return absl::OkStatus();
  }));
  return keys;
}

namespace {

StatusOr<std::vector<database::MergeRecord>> readMergeRecords(const PostgresStore::Impl& impl,
                                                              std::optional<int64_t> target) {
  std::vector<database::MergeRecord> records;
  OBJDB_RETURN_IF_ERROR(impl.read("reading merge records", [&](const pg::Connection& c) -> Status {
    records.clear();
    Params p;
    if (target) p.add(*target);
    OBJDB_ASSIGN_OR_RETURN(
        Result r, c.exec(absl::StrFormat("SELECT %s FROM merge_records %s ORDER BY id",
                                         kMergeRecordColumns, target ? "WHERE target = $1" : ""),
                         p, "reading merge records"));
    for (int row = 0; row < r.rows(); ++row) {
      OBJDB_ASSIGN_OR_RETURN(database::MergeRecord m, readMergeRecord(pgstore::ResultRow(r, row)));
      records.push_back(std::move(m));
    }
    return absl::OkStatus();
  }));
  return records;
}

}  // namespace

StatusOr<std::vector<database::MergeRecord>> PostgresStore::mergeRecords() const {
  return readMergeRecords(*impl_, std::nullopt);
}

StatusOr<std::vector<database::MergeRecord>> PostgresStore::mergeRecordsInto(
    int64_t target) const {
  return readMergeRecords(*impl_, target);
}

}  // namespace objdb::storage
