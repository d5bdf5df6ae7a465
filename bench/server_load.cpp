// server_load: concurrent load at full size — N Ingest streams at once (one synthetic scene
// each, a different object kind on a floor) while R reader threads call GetObject / ListObjects /
// ListSessions / GetStats until the streams are done and at least S seconds have passed, an
// online backup taken when half the frames are
// acknowledged. Then the same sessions one after another on a fresh server, and the two
// databases compared session by session. Prints latency percentiles per call (not asserted:
// 2 shared cores), the status codes seen, whether every stream's acks came in order without gaps,
// the backup's check, and the comparison.
//
//   build/bin/server_load [--streams 8] [--readers 100] [--frames 60] [--seconds 60] [--dir /tmp]
#include <grpcpp/grpcpp.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <map>
#include <mutex>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "core/common/logging.h"
#include "core/sim/generator.h"
#include "core/sim/lounge.h"
#include "core/sim/renderer.h"
#include "core/sim/scene.h"
#include "objdb/v1/objdb.grpc.pb.h"
#include "server/proto_convert.h"
#include "server/server.h"
#include "storage/sqlite/sqlite_store.h"
#include "bench/bench_sessions.h"

namespace objdb {
namespace {

using Clock = std::chrono::steady_clock;
double msSince(Clock::time_point t) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

[[noreturn]] void die(const std::string& what) {
  std::fprintf(stderr, "server_load: %s\n", what.c_str());
  std::exit(1);
}

void setDeadline(grpc::ClientContext* context, double seconds) {
  context->set_deadline(std::chrono::system_clock::now() +
                        std::chrono::milliseconds(int64_t(seconds * 1000)));
}

// What one stream saw.
struct StreamOutcome {
  grpc::Status ingest, end;
  size_t acks = 0;
  bool acks_in_order = true;  // indices 0, 1, 2, … with none missing or repeated
  size_t rejected = 0;        // acks with accepted = false
  double ingest_ms = 0, end_ms = 0;
};

StreamOutcome runStream(v1::ObjectDatabase::Stub& stub,
                        const std::vector<v1::IngestRequest>& requests,
                        std::atomic<size_t>* acked_frames) {
  StreamOutcome out;
  const std::string& name = requests[0].header().session_name();
  auto t = Clock::now();
  {
    grpc::ClientContext context;
    setDeadline(&context, 1800);
    auto stream = stub.Ingest(&context);
    std::thread reader([&] {
      v1::IngestResponse response;
      while (stream->Read(&response)) {
        if (!response.has_ack()) continue;
        if (response.ack().index() != out.acks) out.acks_in_order = false;
        out.rejected += response.ack().accepted() ? 0 : 1;
        ++out.acks;
        acked_frames->fetch_add(1);
      }
    });
    for (const auto& r : requests) {
      if (!stream->Write(r)) break;
    }
    stream->WritesDone();
    reader.join();
    out.ingest = stream->Finish();
  }
  out.ingest_ms = msSince(t);
  t = Clock::now();
  grpc::ClientContext context;
  setDeadline(&context, 1800);
  v1::EndSessionRequest request;
  request.set_session_name(name);
  v1::EndSessionResponse response;
  out.end = stub.EndSession(&context, request, &response);
  out.end_ms = msSince(t);
  return out;
}

// Latencies (ms) and status codes of one kind of call, over all reader threads.
struct CallStats {
  std::vector<double> ms;
  std::map<grpc::StatusCode, size_t> codes;
  void add(const CallStats& o) {
    ms.insert(ms.end(), o.ms.begin(), o.ms.end());
    for (const auto& [c, n] : o.codes) codes[c] += n;
  }
};

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, size_t(p * double(v.size() - 1) + 0.5))];
}

const char* codeName(grpc::StatusCode code) {
  switch (code) {
    case grpc::StatusCode::OK: return "OK";
    case grpc::StatusCode::NOT_FOUND: return "NOT_FOUND";
    case grpc::StatusCode::DEADLINE_EXCEEDED: return "DEADLINE_EXCEEDED";
    case grpc::StatusCode::UNAVAILABLE: return "UNAVAILABLE";
    case grpc::StatusCode::RESOURCE_EXHAUSTED: return "RESOURCE_EXHAUSTED";
    case grpc::StatusCode::INTERNAL: return "INTERNAL";
    case grpc::StatusCode::UNKNOWN: return "UNKNOWN";
    default: return "other";
  }
}

// Reader thread r: random calls until `stop`, each with a 30 s deadline.
void runReader(v1::ObjectDatabase::Stub& stub, int r, const std::atomic<bool>& stop,
               std::map<std::string, CallStats>* stats) {
  std::mt19937 rng(uint32_t(r) + 1);
  std::vector<uint64_t> ids;
  while (!stop) {
    grpc::ClientContext context;
    setDeadline(&context, 30);
    // No GetObject before a listing has shown an object (it would be NOT_FOUND).
    int op = int(rng() % 4);
    if (op == 1 && ids.empty()) op = 0;
    const auto t = Clock::now();
    grpc::Status status;
    const char* name = "";
    if (op == 0) {
      name = "ListObjects";
      v1::ListObjectsRequest request;
      v1::ListObjectsResponse response;
      status = stub.ListObjects(&context, request, &response);
      if (status.ok()) {
        ids.clear();
        for (const auto& o : response.objects()) ids.push_back(o.id());
      }
    } else if (op == 1) {
      name = "GetObject";
      v1::GetObjectRequest request;
      request.set_id(ids[rng() % ids.size()]);
      request.set_include_cloud(rng() % 2 == 0);
      v1::ObjectDetail response;
      status = stub.GetObject(&context, request, &response);
    } else if (op == 2) {
      name = "ListSessions";
      v1::ListSessionsResponse response;
      status = stub.ListSessions(&context, v1::ListSessionsRequest(), &response);
    } else {
      name = "GetStats";
      v1::GetStatsResponse response;
      status = stub.GetStats(&context, v1::GetStatsRequest(), &response);
    }
    CallStats& s = (*stats)[name];
    s.ms.push_back(msSince(t));
    ++s.codes[status.error_code()];
  }
}

// One object as the comparison sees it: sizes and a hash of its surface cloud.
struct ObjectFacts {
  uint32_t points = 0, voxels = 0, poses = 0, merges = 0;
  uint64_t cloud_hash = 0;
  auto operator<=>(const ObjectFacts&) const = default;
};

// FNV-1a over the cloud's point and normal floats, bit for bit.
uint64_t cloudHash(const v1::PointCloud& cloud) {
  uint64_t h = 1469598103934665603ull;
  auto mix = [&h](const auto& values) {
    for (const float v : values) {
      uint32_t bits;
      std::memcpy(&bits, &v, sizeof bits);
      for (int b = 0; b < 4; ++b) h = (h ^ ((bits >> (8 * b)) & 0xFF)) * 1099511628211ull;
    }
  };
  mix(cloud.points());
  mix(cloud.normals());
  return h;
}

// session → the facts of its active objects, sorted.
std::map<std::string, std::vector<ObjectFacts>> databaseFacts(v1::ObjectDatabase::Stub& stub,
                                                              const std::vector<std::string>& sessions) {
  std::map<std::string, std::vector<ObjectFacts>> out;
  for (const auto& session : sessions) {
    grpc::ClientContext context;
    setDeadline(&context, 120);
    v1::ListObjectsRequest request;
    request.set_session_name(session);
    request.set_page_size(1000);
    v1::ListObjectsResponse listed;
    const grpc::Status status = stub.ListObjects(&context, request, &listed);
    if (!status.ok()) die("ListObjects " + session + ": " + status.error_message());
    auto& facts = out[session];
    for (const auto& o : listed.objects()) {
      grpc::ClientContext get_context;
      setDeadline(&get_context, 120);
      v1::GetObjectRequest get;
      get.set_id(o.id());
      get.set_include_cloud(true);
      v1::ObjectDetail detail;
      const grpc::Status got = stub.GetObject(&get_context, get, &detail);
      if (!got.ok()) die("GetObject: " + got.error_message());
      facts.push_back({detail.stats().num_points(), detail.stats().num_voxels(),
                       uint32_t(detail.poses_size()), detail.stats().num_merges(),
                       cloudHash(detail.cloud())});
    }
    std::sort(facts.begin(), facts.end());
  }
  return out;
}

std::unique_ptr<ObjdbServer> startServer(const std::string& db) {
  for (const char* suffix : {"", "-wal", "-shm", "-journal"}) std::filesystem::remove(db + suffix);
  ServerOptions options;
  options.listen_address = "127.0.0.1:0";
  options.db_path = db;
  options.drain_deadline = std::chrono::seconds(60);
  options.max_open_sessions = 64;
  auto server = ObjdbServer::start(options);
  if (!server.ok()) die("cannot start the server: " + std::string(server.status().message()));
  return std::move(*server);
}

std::unique_ptr<v1::ObjectDatabase::Stub> stubFor(const ObjdbServer& server) {
  grpc::ChannelArguments args;
  args.SetMaxReceiveMessageSize(64 << 20);
  return v1::ObjectDatabase::NewStub(
      grpc::CreateCustomChannel(server.address(), grpc::InsecureChannelCredentials(), args));
}

}  // namespace
}  // namespace objdb

int main(int argc, char** argv) {
  using namespace objdb;
  int streams = 8, readers = 100, frames = 60;
  double seconds = 60;
  std::string dir = "/tmp";
  const char* usage =
      "usage: server_load [--streams N] [--readers N] [--frames N] [--seconds S] [--dir DIR]\n";
  for (int i = 1; i < argc; i += 2) {
    const std::string name = argv[i];
    if (i + 1 >= argc) {
      std::fputs(usage, stderr);
      return 2;
    }
    const std::string value = argv[i + 1];
    if (name == "--streams") {
      streams = std::atoi(value.c_str());
    } else if (name == "--readers") {
      readers = std::atoi(value.c_str());
    } else if (name == "--frames") {
      frames = std::atoi(value.c_str());
    } else if (name == "--seconds") {
      seconds = std::atof(value.c_str());
    } else if (name == "--dir") {
      dir = value;
    } else {
      std::fputs(usage, stderr);
      return 2;
    }
  }
  if (streams < 1 || streams > int(bench::objectKinds().size()) || readers < 0 || readers > 1000 || frames < 2 ||
      frames > 1000 || !(seconds > 0)) {
    std::fprintf(stderr, "server_load: --streams 1..%zu (one object kind each), --readers 0..1000, "
                         "--frames 2..1000, --seconds > 0\n", bench::objectKinds().size());
    return 2;
  }
  setLogLevel("warn");

  std::vector<std::vector<v1::IngestRequest>> sessions;
  std::vector<std::string> names;
  auto t = Clock::now();
  for (int s = 0; s < streams; ++s) {
    const std::string& kind = bench::objectKinds()[size_t(s)];
    names.push_back("load_" + std::to_string(s) + "_" + kind);
    auto rendered = bench::renderSession(names.back(), kind, frames, "tango", "server_load");
    if (!rendered.ok()) die("cannot build the scene of " + kind + ": " + rendered.status().ToString());
    sessions.push_back(*std::move(rendered));
  }
  std::printf("%d sessions of %d Tango frames rendered in %.1f s (one object kind each on a floor)\n",
              streams, frames, msSince(t) / 1000);

  // --- Concurrent run --------------------------------------------------------------------
  const std::string concurrent_db = (std::filesystem::path(dir) / "server_load_concurrent.sqlite").string();
  const std::string backup_path = (std::filesystem::path(dir) / "server_load_backup.sqlite").string();
  for (const char* suffix : {"", "-wal", "-shm", "-journal"}) {
    std::filesystem::remove(backup_path + suffix);
  }
  auto server = startServer(concurrent_db);
  auto stub = stubFor(*server);
  std::atomic<bool> stop{false};
  std::atomic<size_t> acked{0};
  std::vector<std::map<std::string, CallStats>> reader_stats(static_cast<size_t>(readers));
  std::vector<std::thread> reader_threads;
  t = Clock::now();
  for (int r = 0; r < readers; ++r) {
    reader_threads.emplace_back([&, r] { runReader(*stub, r, stop, &reader_stats[size_t(r)]); });
  }
  std::vector<StreamOutcome> outcomes(static_cast<size_t>(streams));
  std::vector<std::thread> stream_threads;
  for (int s = 0; s < streams; ++s) {
    stream_threads.emplace_back(
        [&, s] { outcomes[size_t(s)] = runStream(*stub, sessions[size_t(s)], &acked); });
  }
  // The backup, when half of all frames are acknowledged.
  std::string backup_line = "not taken (the run ended first)";
  bool backup_ok = false;
  std::thread backup([&] {
    const size_t half = size_t(streams) * size_t(frames) / 2;
    while (!stop && acked < half) std::this_thread::sleep_for(std::chrono::milliseconds(20));
    if (stop) return;
    const size_t acked_then = acked;
    const auto b = Clock::now();
    const auto report = server->store().backupTo(backup_path);
    const double backup_ms = msSince(b);
    if (!report.ok()) {
      backup_line = "FAILED: " + std::string(report.status().message());
      return;
    }
    storage::SqliteStoreOptions read_only;
    read_only.read_only = true;
    auto copy = storage::SqliteStore::open(backup_path, read_only);
    if (!copy.ok()) {
      backup_line = "taken, but does not open: " + std::string(copy.status().message());
      return;
    }
    const auto check = (*copy)->check();
    const auto stats = (*copy)->stats();
    char line[256];
    backup_ok = check.ok() && check->ok();
    std::snprintf(line, sizeof line, "taken at %zu acked frames in %.0f ms; check %s (%zu blobs), %lld active models",
                  acked_then, backup_ms, backup_ok ? "ok" : "FAILED",
                  check.ok() ? check->blobs_checked : size_t(0),
                  stats.ok() ? (long long)stats->active_models : -1ll);
    backup_line = line;
  });
  for (auto& th : stream_threads) th.join();
  const double streams_s = msSince(t) / 1000;
  // Readers go on until `seconds` have passed since the start.
  while (msSince(t) < seconds * 1000) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  stop = true;
  for (auto& th : reader_threads) th.join();
  backup.join();
  const double run_s = msSince(t) / 1000;

  std::printf("\nConcurrent run: %d streams + %d readers, streams done in %.1f s, readers stopped at %.1f s\n",
              streams, readers, streams_s, run_s);
  std::printf("%-28s %8s %8s %6s %10s %10s  %s\n", "session", "ingest s", "end s", "acks",
              "in order", "rejected", "status (ingest / end)");
  bool all_ok = true;
  for (int s = 0; s < streams; ++s) {
    const StreamOutcome& o = outcomes[size_t(s)];
    const bool ok = o.ingest.ok() && o.end.ok() && o.acks == size_t(frames) && o.acks_in_order;
    all_ok = all_ok && ok;
    std::printf("%-28s %8.1f %8.1f %6zu %10s %10zu  %s / %s\n", names[size_t(s)].c_str(),
                o.ingest_ms / 1000, o.end_ms / 1000, o.acks, o.acks_in_order ? "yes" : "NO",
                o.rejected, o.ingest.ok() ? "OK" : o.ingest.error_message().c_str(),
                o.end.ok() ? "OK" : o.end.error_message().c_str());
  }
  std::map<std::string, CallStats> calls;
  for (const auto& per_reader : reader_stats) {
    for (const auto& [name, s] : per_reader) calls[name].add(s);
  }
  std::printf("\n%-14s %8s %9s %9s %9s %9s  %s\n", "call", "count", "p50 ms", "p90 ms", "p99 ms",
              "max ms", "codes");
  size_t unknown_or_internal = 0, unavailable = 0;
  for (const auto& [name, s] : calls) {
    std::string codes;
    for (const auto& [c, n] : s.codes) {
      codes += std::string(codes.empty() ? "" : ", ") + codeName(c) + " " + std::to_string(n);
      if (c == grpc::StatusCode::UNKNOWN || c == grpc::StatusCode::INTERNAL) unknown_or_internal += n;
      // SQLITE_BUSY would reach a client as UNAVAILABLE.
      if (c == grpc::StatusCode::UNAVAILABLE) unavailable += n;
    }
    std::printf("%-14s %8zu %9.1f %9.1f %9.1f %9.1f  %s\n", name.c_str(), s.ms.size(),
                percentile(s.ms, 0.5), percentile(s.ms, 0.9), percentile(s.ms, 0.99),
                percentile(s.ms, 1.0), codes.c_str());
  }
  std::printf("UNKNOWN/INTERNAL answers: %zu, UNAVAILABLE: %zu\nbackup: %s\n", unknown_or_internal,
              unavailable, backup_line.c_str());
  const auto concurrent = databaseFacts(*stub, names);
  stub.reset();
  server.reset();

  // --- The same sessions one after another ----------------------------------------------
  const std::string sequential_db = (std::filesystem::path(dir) / "server_load_sequential.sqlite").string();
  server = startServer(sequential_db);
  stub = stubFor(*server);
  t = Clock::now();
  for (int s = 0; s < streams; ++s) {
    std::atomic<size_t> ignored{0};
    const StreamOutcome o = runStream(*stub, sessions[size_t(s)], &ignored);
    if (!o.ingest.ok() || !o.end.ok()) die("sequential run: " + names[size_t(s)] + " failed");
  }
  std::printf("\nSequential run: %d sessions one after another in %.1f s\n", streams, msSince(t) / 1000);
  const auto sequential = databaseFacts(*stub, names);
  stub.reset();
  server.reset();

  std::printf("\n%-28s %10s %10s  %s\n", "session", "objects", "(sequential)", "same objects");
  size_t differing = 0;
  for (const auto& name : names) {
    const auto& a = concurrent.at(name);
    const auto& b = sequential.at(name);
    const bool same = a == b;
    differing += same ? 0 : 1;
    std::printf("%-28s %10zu %10zu    %s\n", name.c_str(), a.size(), b.size(), same ? "yes" : "NO");
  }
  std::printf("\nsessions whose objects differ between the runs (points, voxels, poses, merges, cloud hash): %zu of %d\n",
              differing, streams);
  // Exit 1 on any failure: a stream or ack problem, UNKNOWN/INTERNAL/UNAVAILABLE answers, a
  // missing or damaged backup, or objects that differ from the sequential run.
  return all_ok && unknown_or_internal == 0 && unavailable == 0 && backup_ok && differing == 0 ? 0 : 1;
}
