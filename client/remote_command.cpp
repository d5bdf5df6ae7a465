// `objdb remote`: the query RPCs of a running objdb server — statistics, sessions, objects, one
// object's geometry, a session's (completed) scene mesh — the on-line counterpart of `objdb db`.
#include <cmath>
#include <cstdio>
#include <optional>
#include <string>
#include <vector>

#include "absl/strings/str_format.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_split.h"
#include "client/cli_util.h"
#include "client/commands.h"
#include "client/remote.h"
#include "core/io/mesh_io.h"
#include "server/proto_convert.h"

namespace objdb {
namespace {

constexpr const char* kCommand = "remote";

constexpr const char* kUsage = R"(usage: objdb remote stats    [--server HOST:PORT]
       objdb remote sessions [--server HOST:PORT]
       objdb remote objects  [--server HOST:PORT] [--session NAME] [--merged] [--structure]
                             [--parts]
       objdb remote object   [--server HOST:PORT] --id ID [--out FILE.ply --what mesh|cloud]
       objdb remote scene    [--server HOST:PORT] --session NAME --out FILE.ply [--completed]
       objdb remote match    [--server HOST:PORT] (--id ID | --cloud FILE.ply [--viewpoint X,Y,Z])
                             [--max-results N]
       objdb remote here     [--server HOST:PORT] --session NAME
                             (--box X0,Y0,Z0,X1,Y1,Z1 | --ball X,Y,Z,R) [--structure]
       objdb remote changes  [--server HOST:PORT] --from NAME --to NAME [--structure]

Asks a running objdb server (objdb-server) about its database.

  stats     server and database statistics (GetStats)
  sessions  every session: state, frames, start and end time, client (ListSessions)
  objects   the whole objects, one line each: sessions, poses, extent, surface (object or
            planar) (ListObjects; every page); --structure lists room structure too (floors,
            walls, partitions), --parts adds a line per part of each object at each pose (its
            GSM label, voxels and extent)
  object    one object's poses, parts and statistics (GetObject); with --out its mesh (default)
            or its surface cloud with normals, in the object's base frame, as PLY
  scene     a session's mesh in its world frame as PLY (GetSceneMesh); --completed fills what the
            session never saw with the database's merged models
  match     "what is this?" (Match): the stored objects a cloud (PLY: x y z, with normals and
            colours if it has them) or a stored object (--id: find similar) would merge with,
            each with its pose and evidence, the best first; nothing is written. A cloud without
            normals is a sensor's, seen from --viewpoint (default its frame's origin); one with
            normals is seen from all sides
  here      "what is here?" (ObjectsInRegion): the objects whose placement's centre lies in a
            box (min then max corner) or a ball (centre, radius) of a session's world, metres
  changes   what changed between two sessions of one world (SessionChanges): objects added,
            removed, and moved (a placement with none of the same object within 5 cm in the
            other session)

)" OBJDB_CONNECTION_USAGE R"(  --timeout S          seconds a call may take (default 600)
  -h, --help           show this text
)";

struct Options {
  cli::Connection connection;
  std::string session, out, what = "mesh";
  long long id = 0, max_results = 10;
  std::string cloud, from, to;
  std::optional<Eigen::Vector3d> viewpoint;
  std::vector<double> box, ball;  // 6 and 4 numbers
  bool merged = false, completed = false, structure = false, parts = false;
  double timeout_s = 600.0;
};

std::string extent(const v1::BoundingBox& box) {
  return absl::StrFormat("%.2f x %.2f x %.2f", box.max().x() - box.min().x(),
                         box.max().y() - box.min().y(), box.max().z() - box.min().z());
}

int stats(v1::ObjectDatabase::Stub& stub, const Options& o) {
  grpc::ClientContext context;
  cli::setDeadline(&context, o.timeout_s);
  v1::GetStatsResponse s;
  const grpc::Status status = stub.GetStats(&context, v1::GetStatsRequest(), &s);
  if (!status.ok()) return cli::reportRpcError(kCommand, "GetStats", o.connection.server, status);
  std::printf("server %s, version %s, up %.0f s\n", o.connection.server.c_str(), s.server_version().c_str(),
              s.uptime_s());
  std::printf("sessions: %llu (%u streaming now), %llu frames integrated\n",
              (unsigned long long)s.sessions_total(), s.sessions_open(),
              (unsigned long long)s.frames_integrated());
  std::printf("objects: %llu active, %llu merged; %llu raw segments; %u segments queued\n",
              (unsigned long long)s.objects_active(), (unsigned long long)s.objects_merged(),
              (unsigned long long)s.segments_total(), s.queued_segments());
  std::printf("database: %.1f MB on disk; %llu jobs cancelled, %llu unreadable candidates skipped\n",
              double(s.database_size_bytes()) / 1e6, (unsigned long long)s.jobs_cancelled(),
              (unsigned long long)s.candidates_skipped());
  std::printf("scene checks: %llu poses verified, %llu candidates rejected by them, %llu poses "
              "without a scene map\n",
              (unsigned long long)s.scene_checks(),
              (unsigned long long)s.candidates_rejected_by_scene(),
              (unsigned long long)s.poses_without_scene());
  std::printf("inserts: %llu, %.2f s in the database stage, %.2f s waiting for the writer lock, "
              "%.2f s under it\n",
              (unsigned long long)s.insert_timings().inserts(), s.insert_timings().total_s(),
              s.insert_timings().writer_wait_s(), s.insert_timings().writer_hold_s());
  std::printf("leases: %llu sessions of stopped servers taken over, %llu leases lost\n",
              (unsigned long long)s.sessions_taken_over(), (unsigned long long)s.leases_lost());
  std::printf("live maps across servers: %llu published (%.2f s), %llu of other servers read\n",
              (unsigned long long)s.maps_published(), s.map_publish_s(),
              (unsigned long long)s.published_maps_read());
  return 0;
}

int sessions(v1::ObjectDatabase::Stub& stub, const Options& o) {
  v1::ListSessionsRequest request;
  std::printf("%-24s %-12s %8s %10s %10s  %s\n", "session", "state", "frames", "segments",
              "created", "client");
  while (true) {
    grpc::ClientContext context;
    cli::setDeadline(&context, o.timeout_s);
    v1::ListSessionsResponse page;
    const grpc::Status status = stub.ListSessions(&context, request, &page);
    if (!status.ok()) return cli::reportRpcError(kCommand, "ListSessions", o.connection.server, status);
    for (const auto& s : page.sessions()) {
      std::string state = v1::SessionState_Name(s.state());
      state = state.substr(std::string("SESSION_STATE_").size());
      // Counters a crash lost are unknown ("?"), not zero.
      auto count = [&](uint64_t n, bool known) {
        return known ? std::to_string(n) : std::string("?");
      };
      const bool known = !s.counters_unknown();
      const v1::SessionCounters& c = s.counters();
      std::printf("%-24s %-12s %8s %10s %10s  %s\n", s.session_name().c_str(), state.c_str(),
                  count(c.frames_integrated(), known || c.frames_integrated() > 0).c_str(),
                  count(c.segments_extracted(), known).c_str(),
                  count(c.objects_created(), known).c_str(), s.client_info().c_str());
    }
    if (page.next_page_token().empty()) return 0;
    request.set_page_token(page.next_page_token());
  }
}

void printParts(const google::protobuf::RepeatedPtrField<v1::ObjectPart>& parts) {
  for (const auto& p : parts) {
    std::printf("           part %-6u of %-20s segment %-6llu %6u voxels, extent %s m\n", p.label(),
                p.session_name().c_str(), (unsigned long long)p.segment_id(), p.num_voxels(),
                extent(p.bounds_object()).c_str());
  }
}

int objects(v1::ObjectDatabase::Stub& stub, const Options& o) {
  v1::ListObjectsRequest request;
  request.set_session_name(o.session);
  request.set_include_merged(o.merged);
  request.set_include_structure(o.structure);
  request.set_include_parts(o.parts);
  request.set_page_size(1000);
  size_t count = 0;
  std::printf("%8s %-7s %6s %6s %-22s %-9s  %s\n", "id", "state", "poses", "places",
              "extent (m)", "surface", "sessions");
  while (true) {
    grpc::ClientContext context;
    cli::setDeadline(&context, o.timeout_s);
    v1::ListObjectsResponse page;
    const grpc::Status status = stub.ListObjects(&context, request, &page);
    if (!status.ok()) return cli::reportRpcError(kCommand, "ListObjects", o.connection.server, status);
    for (const auto& m : page.objects()) {
      std::printf("%8llu %-7s %6u %6u %-22s %-9s  %s\n", (unsigned long long)m.id(),
                  m.state() == v1::OBJECT_STATE_MERGED ? "merged" : "active", m.num_poses(),
                  m.num_places(), extent(m.bounds_object()).c_str(),
                  m.structure() ? "structure" : m.planar() ? "planar" : "object",
                  absl::StrJoin(m.session_names(), ", ").c_str());
      printParts(m.parts());
      ++count;
    }
    if (page.next_page_token().empty()) break;
    request.set_page_token(page.next_page_token());
  }
  std::printf("%zu objects\n", count);
  return 0;
}

int object(v1::ObjectDatabase::Stub& stub, const Options& o) {
  grpc::ClientContext context;
  cli::setDeadline(&context, o.timeout_s);
  v1::GetObjectRequest request;
  request.set_id(uint64_t(o.id));
  request.set_include_mesh(!o.out.empty() && o.what == "mesh");
  request.set_include_cloud(!o.out.empty() && o.what == "cloud");
  request.set_include_parts(true);
  v1::ObjectDetail d;
  const grpc::Status status = stub.GetObject(&context, request, &d);
  if (!status.ok()) return cli::reportRpcError(kCommand, "GetObject", o.connection.server, status);
  std::printf("object %llu: %s, %s, extent %s m, %u points, %u keypoints, %u voxels of %.3f m, "
              "%u merges\n",
              (unsigned long long)d.summary().id(),
              d.summary().state() == v1::OBJECT_STATE_MERGED ? "merged" : "active",
              d.summary().structure() ? "structure"
              : d.summary().planar()  ? "planar"
                                      : "not planar",
              extent(d.summary().bounds_object()).c_str(), d.stats().num_points(),
              d.stats().num_keypoints(), d.stats().num_voxels(), d.stats().voxel_size_m(),
              d.stats().num_merges());
  for (const auto& p : d.poses()) {
    const auto& T = p.t_world_object();
    std::printf("  seen in %-20s at (%.3f, %.3f, %.3f), q (%.4f, %.4f, %.4f, %.4f), segment %llu\n",
                p.session_name().c_str(), T.x(), T.y(), T.z(), T.qx(), T.qy(), T.qz(), T.qw(),
                (unsigned long long)p.segment_id());
  }
  printParts(d.parts());
  for (const auto& m : d.merges()) {
    std::printf("  merged %-26s e_ICP %.4f m, e_TSDF %.4f m, o_TSDF %llu, %u scene checks\n",
                m.source().c_str(), m.icp_rmse_m(), m.tsdf_rmse_m(),
                (unsigned long long)m.overlap_voxels(), m.scene_checks());
  }
  if (o.out.empty()) return 0;
  const Status written =
      o.what == "mesh" ? io::writePlyMesh(o.out, server::meshFromProto(d.mesh()))
                       : io::writePlyCloud(o.out, server::cloudFromProto(d.cloud()));
  if (!written.ok()) return cli::reportError(kCommand, written);
  std::printf("%s written to %s\n", o.what.c_str(), o.out.c_str());
  return 0;
}

int scene(v1::ObjectDatabase::Stub& stub, const Options& o) {
  TriangleMesh mesh;
  size_t chunks = 0;
  const grpc::Status status =
      cli::fetchSceneMesh(stub, o.session, o.completed, o.timeout_s, &mesh, &chunks);
  if (!status.ok()) return cli::reportRpcError(kCommand, "GetSceneMesh", o.connection.server, status);
  if (Status written = io::writePlyMesh(o.out, mesh); !written.ok()) {
    return cli::reportError(kCommand, written);
  }
  std::printf("session %s%s: %zu chunks, %zu vertices, %zu triangles, %.2f m² written to %s\n",
              o.session.c_str(), o.completed ? " (completed)" : "", chunks, mesh.vertices.size(),
              mesh.triangles.size(), mesh.surfaceArea(), o.out.c_str());
  return 0;
}

// Comma-separated finite numbers, exactly `count` of them.
bool parseNumbers(const std::string& text, size_t count, std::vector<double>* out) {
  out->clear();
  for (absl::string_view part : absl::StrSplit(text, ',')) {
    double x = 0.0;
    if (!absl::SimpleAtod(part, &x) || !std::isfinite(x)) return false;
    out->push_back(x);
  }
  return out->size() == count;
}

std::string place(const v1::Vector3& v) {
  return absl::StrFormat("(%.2f, %.2f, %.2f)", v.x(), v.y(), v.z());
}

int here(v1::ObjectDatabase::Stub& stub, const Options& o) {
  v1::ObjectsInRegionRequest request;
  request.set_session_name(o.session);
  request.set_include_structure(o.structure);
  if (!o.box.empty()) {
    server::setVector({o.box[0], o.box[1], o.box[2]}, request.mutable_box()->mutable_min());
    server::setVector({o.box[3], o.box[4], o.box[5]}, request.mutable_box()->mutable_max());
  } else {
    server::setVector({o.ball[0], o.ball[1], o.ball[2]}, request.mutable_ball()->mutable_centre());
    request.mutable_ball()->set_radius_m(o.ball[3]);
  }
  grpc::ClientContext context;
  cli::setDeadline(&context, o.timeout_s);
  v1::ObjectsInRegionResponse r;
  const grpc::Status status = stub.ObjectsInRegion(&context, request, &r);
  if (!status.ok()) {
    return cli::reportRpcError(kCommand, "ObjectsInRegion", o.connection.server, status);
  }
  std::printf("%8s %-9s %-22s %-22s  %s\n", "id", "surface", "centre (m)", "extent (m)", "sessions");
  for (const auto& p : r.placements()) {
    const auto& m = p.object();
    std::printf("%8llu %-9s %-22s %-22s  %s\n", (unsigned long long)m.id(),
                m.structure() ? "structure" : m.planar() ? "planar" : "object",
                place(p.centre_world()).c_str(), extent(p.bounds_world()).c_str(),
                absl::StrJoin(m.session_names(), ", ").c_str());
  }
  std::printf("%d placements in the region of session %s\n", r.placements_size(),
              o.session.c_str());
  return 0;
}

int changes(v1::ObjectDatabase::Stub& stub, const Options& o) {
  v1::SessionChangesRequest request;
  request.set_from_session(o.from);
  request.set_to_session(o.to);
  request.set_include_structure(o.structure);
  grpc::ClientContext context;
  cli::setDeadline(&context, o.timeout_s);
  v1::SessionChangesResponse r;
  const grpc::Status status = stub.SessionChanges(&context, request, &r);
  if (!status.ok()) {
    return cli::reportRpcError(kCommand, "SessionChanges", o.connection.server, status);
  }
  auto list = [](const char* what, const auto& changes) {
    for (const auto& c : changes) {
      std::string where;
      for (const auto& p : c.after().empty() ? c.before() : c.after()) {
        where += absl::StrFormat(" (%.2f, %.2f, %.2f)", p.x(), p.y(), p.z());
      }
      std::printf("%-8s %8llu%s%s\n", what, (unsigned long long)c.object().id(),
                  c.moved_m() > 0.0 ? absl::StrFormat(" by %.2f m, now at", c.moved_m()).c_str()
                                    : " at",
                  where.c_str());
    }
  };
  list("added", r.added());
  list("removed", r.removed());
  list("moved", r.moved());
  std::printf("from %s to %s: %d added, %d removed, %d moved, %u unchanged\n", o.from.c_str(),
              o.to.c_str(), r.added_size(), r.removed_size(), r.moved_size(), r.unchanged());
  return 0;
}

int match(v1::ObjectDatabase::Stub& stub, const Options& o) {
  v1::MatchRequest request;
  request.set_max_results(uint32_t(o.max_results));
  if (!o.cloud.empty()) {
    auto read = io::readMesh(o.cloud);
    if (!read.ok()) return cli::reportError(kCommand, read.status());
    PointCloud cloud{read->vertices, read->normals, read->colors};
    server::toProto(cloud, request.mutable_cloud());
    if (o.viewpoint) server::setVector(*o.viewpoint, request.mutable_viewpoint());
  } else {
    request.set_object_id(uint64_t(o.id));
  }
  grpc::ClientContext context;
  cli::setDeadline(&context, o.timeout_s);
  v1::MatchResponse r;
  const grpc::Status status = stub.Match(&context, request, &r);
  if (!status.ok()) return cli::reportRpcError(kCommand, "Match", o.connection.server, status);
  const std::string what =
      o.cloud.empty() ? "object " + std::to_string(o.id) : "cloud " + o.cloud;
  std::printf("%s: %u surface points, %u keypoints; %u models voted over%s, %u candidates "
              "evaluated in %.2f s\n",
              what.c_str(), r.points(), r.keypoints(), r.shortlist(),
              r.shortlist() == 0 ? " (all)" : "", r.candidates(), r.elapsed_s());
  if (!r.matchable()) {
    std::printf("not matched: %s\n", r.reason().c_str());
    return 0;
  }
  size_t accepted = 0;
  for (const auto& m : r.results()) {
    const auto& T = m.t_object_query();
    const auto& e = m.evidence();
    accepted += m.accepted() ? 1 : 0;
    std::printf("%8llu %-9s inliers %4u, e_ICP %.4f m, e_TSDF %.4f m, o_TSDF %6llu, %u scene "
                "checks; query at (%.3f, %.3f, %.3f), q (%.4f, %.4f, %.4f, %.4f) in its frame\n",
                (unsigned long long)m.object_id(), m.accepted() ? "match" : m.stage().c_str(),
                m.inliers(), e.icp_rmse_m(), e.tsdf_rmse_m(),
                (unsigned long long)e.overlap_voxels(), e.scene_checks(), T.x(), T.y(), T.z(),
                T.qx(), T.qy(), T.qz(), T.qw());
    if (!m.accepted()) std::printf("         %s\n", m.reason().c_str());
  }
  std::printf("%zu of %d shown would merge\n", accepted, r.results_size());
  return 0;
}

}  // namespace

int runRemoteCommand(int argc, char** argv) {
  if (argc < 2) return cli::usageError(kCommand, "no action given", kUsage);
  const std::string action = argv[1];
  if (action == "-h" || action == "--help") {
    std::fputs(kUsage, stdout);
    return 0;
  }
  Options o;
  bool what_given = false;
  for (int i = 2; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "-h" || a == "--help") {
      std::fputs(kUsage, stdout);
      return 0;
    }
    if (a == "--merged") {
      o.merged = true;
      continue;
    }
    if (a == "--completed") {
      o.completed = true;
      continue;
    }
    if (a == "--structure") {
      o.structure = true;
      continue;
    }
    if (a == "--parts") {
      o.parts = true;
      continue;
    }
    if (i + 1 >= argc) return cli::usageError(kCommand, a + " needs a value", kUsage);
    const char* value = argv[++i];
    long long seconds = 0;
    if (cli::takeConnectionFlag(a, value, &o.connection)) {
    } else if (a == "--session") {
      o.session = value;
    } else if (a == "--out") {
      o.out = value;
    } else if (a == "--what") {
      o.what = value;
      what_given = true;
      if (o.what != "mesh" && o.what != "cloud") {
        return cli::usageError(kCommand, "--what must be mesh or cloud, got " + o.what, kUsage);
      }
    } else if (a == "--id") {
      if (!cli::parseInt(value, 1, INT64_MAX, &o.id)) {
        return cli::usageError(kCommand, std::string("--id needs a positive integer, got ") + value, kUsage);
      }
    } else if (a == "--box" || a == "--ball") {
      const bool box = a == "--box";
      if (!parseNumbers(value, box ? 6 : 4, box ? &o.box : &o.ball)) {
        return cli::usageError(kCommand, a + (box ? " needs X0,Y0,Z0,X1,Y1,Z1" : " needs X,Y,Z,R") +
                                             " in metres, got " + value, kUsage);
      }
    } else if (a == "--from") {
      o.from = value;
    } else if (a == "--to") {
      o.to = value;
    } else if (a == "--cloud") {
      o.cloud = value;
    } else if (a == "--viewpoint") {
      std::vector<double> xyz;
      if (!parseNumbers(value, 3, &xyz)) {
        return cli::usageError(kCommand, std::string("--viewpoint needs X,Y,Z in metres, got ") + value, kUsage);
      }
      o.viewpoint = Eigen::Vector3d(xyz[0], xyz[1], xyz[2]);
    } else if (a == "--max-results") {
      if (!cli::parseInt(value, 0, 1000, &o.max_results)) {
        return cli::usageError(kCommand, std::string("--max-results needs 0..1000 (0: all), got ") + value, kUsage);
      }
    } else if (a == "--timeout") {
      if (!cli::parseInt(value, 1, 86400, &seconds)) {
        return cli::usageError(kCommand, std::string("--timeout needs 1..86400 seconds, got ") + value, kUsage);
      }
      o.timeout_s = double(seconds);
    } else {
      return cli::usageError(kCommand, "unknown option '" + a + "'", kUsage);
    }
  }
  if (o.connection.server.empty()) return cli::usageError(kCommand, "--server is empty", kUsage);
  if (what_given && o.out.empty()) {
    return cli::usageError(kCommand, "--what says what --out FILE.ply gets; give --out too",
                           kUsage);
  }
  auto channel = cli::openChannel(o.connection);
  if (!channel.ok()) return cli::reportError(kCommand, channel.status());
  auto stub = v1::ObjectDatabase::NewStub(*channel);
  if (action == "stats") return stats(*stub, o);
  if (action == "sessions") return sessions(*stub, o);
  if (action == "objects") return objects(*stub, o);
  if (action == "object") {
    if (o.id == 0) return cli::usageError(kCommand, "object needs --id ID", kUsage);
    return object(*stub, o);
  }
  if (action == "match") {
    if ((o.id == 0) == o.cloud.empty()) {
      return cli::usageError(kCommand, "match needs --id ID or --cloud FILE.ply (one of them)",
                             kUsage);
    }
    if (o.viewpoint && o.cloud.empty()) {
      return cli::usageError(kCommand, "--viewpoint goes with --cloud", kUsage);
    }
    return match(*stub, o);
  }
  if (action == "here") {
    if (o.session.empty() || o.box.empty() == o.ball.empty()) {
      return cli::usageError(kCommand, "here needs --session NAME and --box or --ball (one)",
                             kUsage);
    }
    return here(*stub, o);
  }
  if (action == "changes") {
    if (o.from.empty() || o.to.empty()) {
      return cli::usageError(kCommand, "changes needs --from NAME and --to NAME", kUsage);
    }
    return changes(*stub, o);
  }
  if (action == "scene") {
    if (o.session.empty() || o.out.empty()) {
      return cli::usageError(kCommand, "scene needs --session NAME and --out FILE.ply", kUsage);
    }
    return scene(*stub, o);
  }
  return cli::usageError(kCommand, "unknown action \"" + action + "\"", kUsage);
}

}  // namespace objdb
