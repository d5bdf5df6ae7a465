// backpressure_bench: a fast producer against one server. One client writes VGA frames (a chair on
// a floor, 40 views, sent round and round with rising indices) as fast as gRPC lets it, never
// waiting for acks (a second thread reads them), for S seconds. Every 5 s it prints the process's
// resident memory (server and client share the process; the client's part is its 40 encoded
// frames and gRPC's flow-control window, both fixed), the frames written and acknowledged, and the
// write latency: the server blocks a producer it cannot keep up with, so the writes slow down
// instead of its memory growing. At the end: whether the resident memory plateaued (the maximum
// over the last 20 s against the maximum over the 20 s before), and whether every frame written
// was acknowledged as integrated or rejected.
//
//   build/bin/backpressure_bench [--seconds 60] [--dir /tmp]
#include <grpcpp/grpcpp.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "bench/bench_sessions.h"
#include "core/common/logging.h"
#include "objdb/v1/objdb.grpc.pb.h"
#include "server/server.h"

namespace objdb {
namespace {

using Clock = std::chrono::steady_clock;

[[noreturn]] void die(const std::string& what) {
  std::fprintf(stderr, "backpressure_bench: %s\n", what.c_str());
  std::exit(1);
}

double residentMb() {
  std::ifstream status("/proc/self/status");
  std::string line;
  while (std::getline(status, line)) {
    if (line.rfind("VmRSS:", 0) == 0) return std::atof(line.c_str() + 6) / 1024.0;
  }
  return 0.0;
}

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, size_t(p * double(v.size())))];
}

struct Window {
  double rss_max_mb = 0;
  size_t written = 0, acked = 0;
  std::vector<double> write_ms;
};

}  // namespace
}  // namespace objdb

int main(int argc, char** argv) {
  using namespace objdb;
  double seconds = 60;
  std::string dir = "/tmp";
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string name = argv[i];
    if (name == "--seconds") {
      seconds = std::atof(argv[i + 1]);
    } else if (name == "--dir") {
      dir = argv[i + 1];
    } else {
      die("usage: backpressure_bench [--seconds S (>= 45)] [--dir DIR]");
    }
  }
  if (!(seconds >= 45)) die("--seconds must be at least 45 (two 20 s windows and a start)");
  setLogLevel("warn");
  const auto rendered = bench::renderSession("fast", "cube_chair", 40, "vga", "backpressure_bench");
  if (!rendered.ok()) die("cannot render the session: " + rendered.status().ToString());
  const std::vector<v1::IngestRequest>& views = *rendered;

  const std::string db = dir + "/backpressure_bench.sqlite";
  for (const char* suffix : {"", "-wal", "-shm"}) std::filesystem::remove(db + suffix);
  ServerOptions options;
  options.listen_address = "127.0.0.1:0";
  options.db_path = db;
  options.drain_deadline = std::chrono::seconds(5);
  auto server = ObjdbServer::start(options);
  if (!server.ok()) die("cannot start the server: " + server.status().ToString());
  auto stub = v1::ObjectDatabase::NewStub(
      grpc::CreateChannel((*server)->address(), grpc::InsecureChannelCredentials()));

  const double rss_start = residentMb();
  const int windows = int(seconds / 5);
  std::vector<Window> by_window(size_t(windows) + 1);
  std::mutex mutex;
  std::atomic<size_t> written{0}, acked{0}, rejected{0};
  std::atomic<bool> done{false};
  const Clock::time_point start = Clock::now();
  const auto windowOf = [&](Clock::time_point t) {
    return std::min<size_t>(size_t(windows),
                            size_t(std::chrono::duration<double>(t - start).count() / 5.0));
  };

  grpc::ClientContext context;
  auto stream = stub->Ingest(&context);
  std::thread reader([&] {
    v1::IngestResponse response;
    while (stream->Read(&response)) {
      if (!response.has_ack()) continue;
      acked.fetch_add(1);
      rejected.fetch_add(response.ack().accepted() ? 0 : 1);
      std::lock_guard lock(mutex);
      ++by_window[windowOf(Clock::now())].acked;
    }
  });
  std::thread sampler([&] {
    while (!done.load()) {
      const double rss = residentMb();
      {
        std::lock_guard lock(mutex);
        Window& w = by_window[windowOf(Clock::now())];
        w.rss_max_mb = std::max(w.rss_max_mb, rss);
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(250));
    }
  });

  if (!stream->Write(views[0])) die("the header could not be written");
  uint64_t index = 0;
  while (Clock::now() - start < std::chrono::duration<double>(seconds)) {
    v1::IngestRequest request = views[1 + index % (views.size() - 1)];
    request.mutable_frame()->set_index(index);
    request.mutable_frame()->set_timestamp_s(double(index) / 30.0);
    const Clock::time_point t = Clock::now();
    if (!stream->Write(request)) break;
    const double ms = std::chrono::duration<double, std::milli>(Clock::now() - t).count();
    written.fetch_add(1);
    ++index;
    std::lock_guard lock(mutex);
    Window& w = by_window[windowOf(t)];
    ++w.written;
    w.write_ms.push_back(ms);
  }
  stream->WritesDone();
  reader.join();
  const grpc::Status ended = stream->Finish();
  done = true;
  sampler.join();

  std::printf("fast producer, VGA, %.0f s: process RSS %.0f MB after rendering and start\n\n",
              seconds, rss_start);
  std::printf("%8s %10s %10s %10s %14s %14s\n", "t, s", "RSS MB", "written", "acked",
              "write p50 ms", "write p99 ms");
  for (int w = 0; w < windows; ++w) {
    const Window& x = by_window[size_t(w)];
    std::printf("%8d %10.0f %10zu %10zu %14.2f %14.2f\n", 5 * (w + 1), x.rss_max_mb, x.written,
                x.acked, percentile(x.write_ms, 0.5), percentile(x.write_ms, 0.99));
  }
  // The plateau: the last four windows (20 s) against the four before.
  double last = 0, before = 0;
  for (int w = windows - 4; w < windows; ++w) last = std::max(last, by_window[size_t(w)].rss_max_mb);
  for (int w = windows - 8; w < windows - 4; ++w) {
    if (w >= 0) before = std::max(before, by_window[size_t(w)].rss_max_mb);
  }
  std::printf("\nRSS max over the last 20 s / the 20 s before: %.0f / %.0f MB = %.3f (plateau: "
              "<= 1.1)\n",
              last, before, before > 0 ? last / before : 0.0);
  std::printf("frames written %zu, acknowledged %zu (%zu rejected); stream ended: %s\n",
              written.load(), acked.load(), rejected.load(),
              ended.ok() ? "OK" : ended.error_message().c_str());
  (*server)->shutdown();
  for (const char* suffix : {"", "-wal", "-shm"}) std::filesystem::remove(db + suffix);
  return written.load() == acked.load() && ended.ok() ? 0 : 1;
}
