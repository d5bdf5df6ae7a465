// `objdb db`: administration of a database file, read-only — integrity check (SQLite's and every
// blob's checksum), counts and sizes, the model list, export of a model's surface cloud or mesh
// to PLY, a session's scene completed by the merged models (paper §III-C, scene completion) as a
// PLY mesh, and an online backup into a new file. Never writes to the database.
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>

#include <nlohmann/json.hpp>

#include "absl/strings/str_format.h"
#include "client/cli_util.h"
#include "client/commands.h"
#include "client/db_replay.h"
#include "core/common/params_io.h"
#include "core/completion/scene_completion.h"
#include "core/io/mesh_io.h"
#include "core/tsdf/mesh_extraction.h"
#include "storage/open_store.h"
#include "storage/postgres/postgres_store.h"
#include "storage/sqlite/sqlite_store.h"

namespace objdb {
namespace {

constexpr const char* kUsage = R"(usage: objdb db check  --db FILE
       objdb db stats  --db FILE
       objdb db models --db FILE
       objdb db export --db FILE --model ID --out FILE.ply [--what cloud|mesh] [--min-weight W]
       objdb db complete --db FILE --session NAME --out FILE.ply [--config FILE] [--min-weight W]
       objdb db backup --db FILE --out NEW_FILE
       objdb db replay --db FILE [--config FILE]

Administration of an objdb database: an SQLite file (opened read-only; nothing is written to
it) or a PostgreSQL database named by a libpq URI (postgresql://USER@HOST/DB; credentials from
~/.pgpass or PGPASSWORD, TLS as its sslmode asks; docs/storage.md).

  check    SQLite's integrity_check and foreign-key check (PostgreSQL: observations whose raw
           segment row names another segment), then every blob's checksum and
           structure; lists each finding (table, row, column, problem); exit status 1 on any
  stats    schema version, file size, rows and blob bytes per table, models by state, sessions
  models   one line per active model: id, observations, points, keypoints, planar, sessions
  export   the mesh of a model's TSDF grid (--what mesh, the default, as `objdb remote object`
           writes; voxels lighter than --min-weight, default 3, are not meshed) or its surface
           cloud with normals (--what cloud), in the model's own frame, as binary PLY
  complete the session's scene map completed by the merged models: every model built from two or
           more segments is placed where the session saw it and, where it verifies against the
           scene (e*_TSDF, o*_TSDF), fills what the session never observed. Writes the completed
           mesh (session's world frame, binary PLY) and prints each placement: model, GSM label,
           segments, verdict, filled voxels. Parameters: the session's stored ones, then
           --config on top (merging.* thresholds, tsdf.max_weight, tsdf.mesh_min_weight unless
           --min-weight is given)
  backup   a consistent copy of the database in a new file (SQLite's backup API, one read
           snapshot), also while objdb-server writes to it; the copy appears whole under its name
           or not at all, never over an existing file, and is checked like `check` does; exit
           status 1 if anything fails. PostgreSQL: a pg_dump archive (custom format, one
           snapshot; restore with pg_restore into an empty database), pg_dump must be installed
  replay   every raw segment inserted again, in the order its row was created, into one object
           database in memory (parameters: the first session's stored ones, --config on top),
           and the result compared with the store: models as sets of segments, and the number
           of merges. Several servers on one database take one writer lock per insert and
           create a segment's row under it, so when every segment was inserted once (no
           re-extraction or withdrawal, e.g. sessions extracted only at their end) both must be
           the same: the result of one server running the inserts in that order. Exit status 1
           when they differ (each model held by one side only is listed)
)";

constexpr const char* kCommand = "db";

int check(const storage::Store& store) {
  const auto report = store.check();
  if (!report.ok()) return cli::reportError(kCommand, report.status());
  for (const auto& line : report->engine_findings) std::printf("engine: %s\n", line.c_str());
  for (const auto& d : report->damaged) {
    std::printf("damaged: %s row %lld, column %s: %s\n", d.table.c_str(), (long long)d.row,
                d.column.c_str(), d.problem.c_str());
  }
  std::printf("%s: %zu blobs checked, %zu damaged, %zu engine findings: %s\n",
              store.describe().c_str(), report->blobs_checked, report->damaged.size(),
              report->engine_findings.size(), report->ok() ? "ok" : "NOT OK");
  return report->ok() ? 0 : 1;
}

int stats(const storage::Store& store) {
  const auto s = store.stats();
  if (!s.ok()) return cli::reportError(kCommand, s.status());
  std::printf("%s: schema %d, %.2f MB (without the WAL)\n", store.describe().c_str(), s->schema_version,
              double(s->file_bytes) / 1e6);
  std::printf("models: %lld active, %lld removed, %lld merged into others\n",
              (long long)s->active_models, (long long)s->removed_models,
              (long long)s->merged_models);
  std::printf("%-16s %10s %14s\n", "table", "rows", "blob MB");
  for (const auto& t : s->tables) {
    std::printf("%-16s %10lld %14.2f\n", t.table.c_str(), (long long)t.rows,
                double(t.blob_bytes) / 1e6);
  }
  const auto sessions = store.sessions();
  if (!sessions.ok()) return cli::reportError(kCommand, sessions.status());
  for (const auto& session : *sessions) {
    std::printf("session %-20s %-11s frames %-6lld started %s%s%s\n", session.name.c_str(),
                storage::sessionStateName(session.state), (long long)session.frames,
                session.started_at.c_str(), session.ended_at.empty() ? "" : ", ended ",
                session.ended_at.c_str());
  }
  return 0;
}

int models(const storage::Store& store) {
  const auto ids = store.modelIds();
  if (!ids.ok()) return cli::reportError(kCommand, ids.status());
  std::printf("%6s %6s %8s %9s %6s  %s\n", "id", "poses", "points", "keypoints", "planar",
              "observations (session/label)");
  int failures = 0;
  for (int64_t id : *ids) {
    const auto m = store.model(id);
    if (!m.ok()) {
      std::printf("%6lld unreadable: %s\n", (long long)id, std::string(m.status().message()).c_str());
      ++failures;
      continue;
    }
    std::string observations;
    for (const auto& o : (*m)->observations) {
      observations += o.session + "/" + std::to_string(o.label) + " ";
    }
    std::printf("%6lld %6zu %8zu %9zu %6s  %s\n", (long long)id, (*m)->observations.size(),
                (*m)->cloud.points.size(), (*m)->keypoint_indices.size(),
                (*m)->planar ? "yes" : "no", observations.c_str());
  }
  return failures == 0 ? 0 : 1;
}

int exportModel(const storage::Store& store, long long id, const std::string& out,
                const std::string& what, float min_weight) {
  const auto m = store.model(id);
  if (!m.ok()) return cli::reportError(kCommand, m.status());
  Status written;
  size_t count = 0;
  if (what == "cloud") {
    written = io::writePlyCloud(out, (*m)->cloud);
    count = (*m)->cloud.points.size();
  } else {
    const TriangleMesh mesh = tsdf::extractMesh((*m)->grid, min_weight);
    written = io::writePlyMesh(out, mesh);
    count = mesh.vertices.size();
  }
  if (!written.ok()) return cli::reportError(kCommand, written);
  std::printf("model %lld: %s with %s written to %s\n", id, what.c_str(),
              cli::counted(count, what == "cloud" ? "point" : "vertex", what == "cloud" ? "" : "vertices")
                  .c_str(),
              out.c_str());
  return 0;
}

// The parameters a session was processed with (the defaults where the stored text is not a JSON
// object, as in files written before sessions recorded them), then `config` on top. Stored
// parameters that do not apply (an unknown key, a bad value) are an error, never ignored.
StatusOr<Params> sessionParams(const storage::Store& store, const std::string& session,
                               const std::string& config, std::string* origin) {
  OBJDB_ASSIGN_OR_RETURN(const auto sessions, store.sessions());
  Params params;
  *origin = "defaults";
  bool known = false;
  for (const auto& s : sessions) {
    if (s.name != session) continue;
    known = true;
    const auto parsed = nlohmann::json::parse(s.params_json, nullptr, /*allow_exceptions=*/false);
    if (!parsed.is_object()) continue;  // e.g. "config file X" in files of earlier versions
    if (Status applied = applyParamsJson(s.params_json, &params); !applied.ok()) {
      return absl::FailedPreconditionError(absl::StrFormat(
          "session %s: its stored parameters do not apply (%s); written by another version?",
          session, applied.message()));
    }
    *origin = "the session's stored parameters";
  }
  if (!known) {
    return absl::NotFoundError(absl::StrFormat("no session %s in %s", session, store.describe()));
  }
  if (!config.empty()) {
    std::ifstream in(config, std::ios::binary);
    if (!in.is_open()) {
      return absl::NotFoundError(absl::StrFormat("cannot open config file %s", config));
    }
    std::stringstream text;
    text << in.rdbuf();
    if (Status applied = applyParamsJson(text.str(), &params); !applied.ok()) {
      return absl::InvalidArgumentError(
          absl::StrFormat("config file %s: %s", config, applied.message()));
    }
    *origin += " with " + config + " on top";
  }
  return params;
}

int replay(const storage::Store& store, const std::string& config) {
  const auto sessions = store.sessions();
  if (!sessions.ok()) return cli::reportError(kCommand, sessions.status());
  if (sessions->empty()) {
    return cli::reportError(kCommand, absl::FailedPreconditionError(absl::StrFormat(
                                          "%s holds no session: nothing to replay",
                                          store.describe())));
  }
  std::string origin;
  const auto params = sessionParams(store, sessions->front().name, config, &origin);
  if (!params.ok()) return cli::reportError(kCommand, params.status());
  const auto start = std::chrono::steady_clock::now();
  const auto report = cli::replayInCreationOrder(store, *params);
  if (!report.ok()) return cli::reportError(kCommand, report.status());
  std::printf("replayed %zu segments in the order their rows were created, through one database in "
              "memory (%s), in %.1f s\n",
              report->segments, origin.c_str(),
              std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
  std::printf("  models: %zu stored, %zu replayed; merges: %zu stored, %zu replayed\n",
              report->models_stored, report->models_replayed, report->merges_stored,
              report->merges_replayed);
  for (const auto& m : report->only_stored) std::printf("  only in the store: {%s}\n", m.c_str());
  for (const auto& m : report->only_replayed) std::printf("  only in the replay: {%s}\n", m.c_str());
  std::printf("  %s\n", report->same() ? "the same: every model holds the same segments"
                                        : "DIFFERENT");
  return report->same() ? 0 : 1;
}

int complete(const storage::Store& store, const std::string& session, const std::string& out,
             const std::string& config, double min_weight) {
  std::string origin;
  auto params = sessionParams(store, session, config, &origin);
  if (!params.ok()) return cli::reportError(kCommand, params.status());
  if (min_weight >= 0.0) params->tsdf.mesh_min_weight = float(min_weight);
  completion::CompletionReport report;
  auto completed =
      completion::completeScene(store, session, params->merging, params->tsdf, &report);
  if (!completed.ok()) return cli::reportError(kCommand, completed.status());
  const auto scene = store.scene(session);
  if (!scene.ok()) return cli::reportError(kCommand, scene.status());
  const TriangleMesh before = tsdf::extractMesh(**scene, params->tsdf.mesh_min_weight);
  const TriangleMesh after = tsdf::extractMesh(*completed, params->tsdf.mesh_min_weight);
  if (Status written = io::writePlyMesh(out, after); !written.ok()) {
    return cli::reportError(kCommand, written);
  }
  std::printf("session %s (%s): %zu placements of models built from >= 2 segments\n",
              session.c_str(), origin.c_str(), report.placements.size());
  std::printf("%8s %8s %9s  %-50s %8s %14s\n", "model", "label", "segments", "verdict",
              "filled", "near surface");
  size_t verified = 0;
  for (const auto& p : report.placements) {
    verified += p.verified ? 1 : 0;
    const std::string verdict =
        p.verified ? absl::StrFormat("verified (e_TSDF %.4f m, o_TSDF %d)%s",
                                     p.verdict.agreement.rmse, p.verdict.agreement.overlap,
                                     p.blurred ? ", blurred: fills nothing" : "")
                   : "rejected: " + p.verdict.reason;
    std::printf("%8lld %8u %9zu  %-50s %8zu %14zu\n", (long long)p.model_id, p.label,
                p.model_segments, verdict.c_str(), p.filled_voxels, p.filled_surface_voxels);
  }
  std::printf("%zu of %zu placements verified, %zu voxels filled; mesh %.2f m² measured, %.2f m² "
              "completed (%zu vertices) written to %s\n",
              verified, report.placements.size(), report.filled_voxels, before.surfaceArea(),
              after.surfaceArea(), after.vertices.size(), out.c_str());
  return 0;
}

int backup(const storage::Store& store, const std::string& out) {
  const auto start = std::chrono::steady_clock::now();
  const auto report = store.backupTo(out);
  if (!report.ok()) return cli::reportError(kCommand, report.status());
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf("%s: backed up to %s, %lld pages (%.2f MB) in %.2f s\n", store.describe().c_str(),
              out.c_str(), (long long)report->pages, double(report->bytes) / 1e6, seconds);
  // A PostgreSQL backup is a pg_dump archive (pg_restore reads it), not a store to check.
  if (storage::isPostgresTarget(store.describe())) return 0;
  storage::SqliteStoreOptions options;
  options.read_only = true;
  options.create_if_missing = false;
  options.quick_check_on_open = false;  // check() below runs the full integrity check
  const auto copy = storage::SqliteStore::open(out, options);
  if (!copy.ok()) return cli::reportError(kCommand, copy.status());
  return check(**copy);
}

}  // namespace

int runDbCommand(int argc, char** argv) {
  if (argc < 2) return cli::usageError(kCommand, "no action given", kUsage);
  const std::string action = argv[1];
  if (action == "--help" || action == "-h" || action == "help") {
    std::fputs(kUsage, stdout);
    return 0;
  }
  if (action != "check" && action != "stats" && action != "models" && action != "export" &&
      action != "complete" && action != "backup" && action != "replay") {
    return cli::usageError(kCommand, "unknown action \"" + action + "\"", kUsage);
  }
  std::string db, out, what = "mesh", session, config;
  long long model_id = -1;
  double min_weight = -1.0;  // not given: 3 for export, the session's mesh weight for complete
  for (int i = 2; i < argc; ++i) {
    const std::string name = argv[i];
    if (name == "--help" || name == "-h") {
      std::fputs(kUsage, stdout);
      return 0;
    }
    if (i + 1 >= argc) return cli::usageError(kCommand, name + " needs a value", kUsage);
    const char* value = argv[++i];
    if (name == "--db") {
      db = value;
    } else if (name == "--out") {
      out = value;
    } else if (name == "--session") {
      session = value;
    } else if (name == "--config") {
      config = value;
    } else if (name == "--what") {
      what = value;
      if (what != "cloud" && what != "mesh") {
        return cli::usageError(kCommand, "--what must be cloud or mesh, got " + what, kUsage);
      }
    } else if (name == "--model") {
      if (!cli::parseInt(value, 1, (1ll << 62), &model_id)) {
        return cli::usageError(kCommand, std::string("--model needs a positive id, got ") + value,
                               kUsage);
      }
    } else if (name == "--min-weight") {
      char* end = nullptr;
      min_weight = std::strtod(value, &end);
      if (end == value || *end != '\0' || !(min_weight >= 0.0 && min_weight <= 1e6)) {
        return cli::usageError(kCommand, std::string("--min-weight needs a weight >= 0, got ") + value,
                               kUsage);
      }
    } else {
      return cli::usageError(kCommand, "unknown option " + name, kUsage);
    }
  }
  if (db.empty()) return cli::usageError(kCommand, "--db FILE is required", kUsage);
  if (action == "export" && (model_id < 0 || out.empty())) {
    return cli::usageError(kCommand, "export needs --model ID and --out FILE.ply", kUsage);
  }
  if (action == "complete" && (session.empty() || out.empty())) {
    return cli::usageError(kCommand, "complete needs --session NAME and --out FILE.ply", kUsage);
  }
  if (action == "backup" && out.empty()) {
    return cli::usageError(kCommand, "backup needs --out NEW_FILE", kUsage);
  }
  storage::StoreOptions options;
  options.sqlite.read_only = true;
  options.sqlite.create_if_missing = false;
  // check runs the full integrity check itself and lists what it finds.
  options.sqlite.quick_check_on_open = action != "check";
  options.postgres.pool_size = 1;
  const auto store = storage::openStore(db, options);
  if (!store.ok()) return cli::reportError(kCommand, store.status());
  if (action == "check") return check(**store);
  if (action == "stats") return stats(**store);
  if (action == "models") return models(**store);
  if (action == "complete") return complete(**store, session, out, config, min_weight);
  if (action == "backup") return backup(**store, out);
  if (action == "replay") return replay(**store, config);
  return exportModel(**store, model_id, out, what, min_weight < 0.0 ? 3.0f : float(min_weight));
}

}  // namespace objdb
