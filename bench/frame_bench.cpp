// The frame path on real data: each dataset's frames are preloaded and
// encoded as `objdb stream` sends them, then
//  1. offline, one frame at a time as the server's frame worker runs them: decode, filter,
//     points, discontinuities, normals, convexity, labelling, segments (segmentation, one
//     thread), TSDF integration, association, label votes (GSM), extraction (idle labels and
//     the scene snapshot handed to the database) — ms per frame per stage in the nvblox-style
//     table (stage, mean, p90, share), and the map's memory: bytes per allocated voxel (TSDF +
//     label history) and blocks per m² of mapped surface;
//  2. through an in-process server on loopback (a fresh SQLite file): one Ingest stream of
//     --server-frames frames (the first dataset's frames played forward and back), written as
//     fast as the server takes them; acknowledged frames per second, the time from the last
//     ack to the stream's summary (the database's backlog), the database's time per insert
//     (GetStats), and the process's peak RSS.
// Datasets: the folders given, else local copies of the SUN3D study room and desk box if present,
// else 100 VGA frames of the synthetic lounge's first session. Prints tables; asserts nothing
// about time (it exits non-zero only when a stage fails).
//
//   frame_bench [--dataset DIR]... [--server-frames 1000] [--threads 2] [--voxel-size 0.02]
//               [--no-server] [--db FILE] [--shortlist N]
// --shortlist: the server's database.shortlist (0: the descriptor vote over every model, as before
// the short list), to compare the frame rate with and without it.
#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <numeric>
#include <string>
#include <thread>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "bench/bench_util.h"
#include "core/gsm/gsm.h"
#include "core/io/dataset.h"
#include "core/segmentation/depth_segmenter.h"
#include "core/sim/generator.h"
#include "core/sim/lounge.h"
#include "core/sim/renderer.h"
#include "core/sim/scene.h"
#include "objdb/v1/objdb.grpc.pb.h"
#include "server/proto_convert.h"
#include "server/server.h"

namespace objdb {
namespace {

using Clock = std::chrono::steady_clock;
double msSince(Clock::time_point t) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

[[noreturn]] void die(const std::string& message) {
  std::fprintf(stderr, "frame_bench: %s\n", message.c_str());
  std::exit(1);
}

struct Sequence {
  std::string name;
  Intrinsics intrinsics;
  std::vector<v1::Frame> frames;  // as objdb stream sends them (FLOAT32 depth, RGB8 colour)
};

Sequence loadDataset(const std::filesystem::path& dir) {
  auto ds = io::openDataset(dir);
  if (!ds.ok()) die("cannot open " + dir.string() + ": " + std::string(ds.status().message()));
  Sequence seq{dir.parent_path().filename().string() + "/" + dir.filename().string(),
               (*ds)->intrinsics(),
               {}};
  for (size_t i = 0; i < (*ds)->size(); ++i) {
    auto frame = (*ds)->loadFrame(i);
    if (!frame.ok()) die("frame " + std::to_string(i) + ": " + std::string(frame.status().message()));
    v1::Frame f;
    f.set_index(i);
    f.set_timestamp_s(frame->timestamp);
    *f.mutable_t_world_camera() = server::toProto(frame->T_world_camera);
    *f.mutable_depth() = server::encodeDepth(frame->depth);
    if (frame->color) *f.mutable_color() = server::encodeColor(*frame->color);
    seq.frames.push_back(std::move(f));
  }
  return seq;
}

Sequence renderLounge(size_t count) {
  sim::LoungeOptions options;
  options.camera = "vga";
  const std::vector<sim::Scene> scenes = sim::loungePreset(options).value();
  const sim::Scene& scene = scenes.front();
  const auto built = sim::buildScene(scene).value();
  const auto poses = sim::sampleTrajectory(scene.trajectory).value();
  const sim::Renderer renderer(scene.intrinsics);
  Sequence seq{"lounge (synthetic, session 1)", scene.intrinsics, {}};
  const size_t step = std::max<size_t>(1, poses.size() / count);
  for (size_t i = 0; i < poses.size() && seq.frames.size() < count; i += step) {
    const Frame frame = sim::renderFrame(scene, built, renderer, poses[i], i, false);
    v1::Frame f;
    f.set_index(seq.frames.size());
    f.set_timestamp_s(double(seq.frames.size()) / 30.0);
    *f.mutable_t_world_camera() = server::toProto(frame.T_world_camera);
    *f.mutable_depth() = server::encodeDepth(frame.depth);
    if (frame.color) *f.mutable_color() = server::encodeColor(*frame.color);
    seq.frames.push_back(std::move(f));
  }
  return seq;
}

struct Stage {
  const char* name;
  std::vector<double> ms;  // per frame
};

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, size_t(q * double(v.size() - 1) + 0.5))];
}

void printStages(const std::vector<Stage>& stages) {
  double total = 0;
  for (const Stage& s : stages) total += std::accumulate(s.ms.begin(), s.ms.end(), 0.0);
  const size_t frames = stages.front().ms.size();
  std::printf("  %-26s %9s %9s %7s\n", "stage", "mean ms", "p90 ms", "share");
  std::vector<double> per_frame(frames, 0.0);
  for (const Stage& s : stages) {
    const double sum = std::accumulate(s.ms.begin(), s.ms.end(), 0.0);
    for (size_t i = 0; i < frames; ++i) per_frame[i] += s.ms[i];
    std::printf("  %-26s %9.2f %9.2f %6.1f%%\n", s.name, sum / double(frames),
                percentile(s.ms, 0.9), total > 0 ? 100.0 * sum / total : 0.0);
  }
  std::printf("  %-26s %9.2f %9.2f %6.1f%%\n", "whole frame", total / double(frames),
              percentile(per_frame, 0.9), 100.0);
}

// Offline: the server's frame worker, stage by stage.
void runOffline(const Sequence& seq, const Params& params, int threads) {
  auto segmenter = segmentation::DepthSegmenter::create(params.segmentation, seq.intrinsics);
  if (!segmenter.ok()) die(std::string(segmenter.status().message()));
  auto map = gsm::Gsm::create(params.tsdf, params.gsm, seq.intrinsics, threads);
  if (!map.ok()) die(std::string(map.status().message()));
  std::vector<Stage> stages = {{"decode (depth + colour)", {}}, {"filter (invalid, holes)", {}},
                               {"points", {}},                   {"discontinuities", {}},
                               {"normals", {}},                  {"convexity", {}},
                               {"labelling", {}},                {"segments", {}},
                               {"TSDF integration", {}},         {"association", {}},
                               {"label votes", {}},              {"extraction", {}}};
  size_t extracted = 0, segments = 0;
  for (const v1::Frame& f : seq.frames) {
    auto t = Clock::now();
    server::DepthCounts counts;
    auto depth = server::decodeDepth(f.depth(), seq.intrinsics, &counts);
    if (!depth.ok()) die(std::string(depth.status().message()));
    std::optional<ColorImage> color;
    if (f.has_color()) {
      auto decoded = server::decodeColor(f.color(), depth->width, depth->height);
      if (!decoded.ok()) die(std::string(decoded.status().message()));
      color = *std::move(decoded);
    }
    const Transform T = server::fromProto(f.t_world_camera(), "pose").value();
    const double decode_ms = msSince(t);
    // As the server runs it: the label image, no per-segment point lists.
    auto seg = segmenter->segment(*depth, color ? &*color : nullptr, nullptr,
                                  {/*segment_points=*/false});
    if (!seg.ok()) die(std::string(seg.status().message()));
    auto fused = map->integrate(*depth, seg->labels, T, color ? &*color : nullptr);
    if (!fused.ok()) die(std::string(fused.status().message()));
    t = Clock::now();
    std::vector<gsm::RawSegment> out = map->extractIdle(false);
    (void)map->takeWithdrawn();
    // The server snapshots the scene for model-to-scene verification when it extracts.
    if (!out.empty()) (void)map->tsdf().snapshot();
    const double extract_ms = msSince(t);
    extracted += out.size();
    segments += seg->segments.size();
    const auto& st = seg->timings;
    const auto& gt = fused->timings;
    const double values[] = {decode_ms,          st.filter_ms,      st.points_ms,
                             st.discontinuity_ms, st.normals_ms,     st.convexity_ms,
                             st.labels_ms,        st.segments_ms,    gt.integration_ms,
                             gt.association_ms,   gt.voting_ms,      extract_ms};
    for (size_t i = 0; i < stages.size(); ++i) stages[i].ms.push_back(values[i]);
  }
  std::printf("%s: %zu frames %dx%d, %.0f mm voxels, TSDF on %d thread%s, segmentation on one\n",
              seq.name.c_str(), seq.frames.size(), seq.intrinsics.width, seq.intrinsics.height,
              params.tsdf.voxel_size_m * 1000, threads, threads == 1 ? "" : "s");
  printStages(stages);
  // Memory: TSDF voxels and their label history, per allocated voxel.
  const tsdf::TsdfLayer& layer = map->tsdf();
  const size_t vpb = size_t(layer.voxelsPerSide()) * layer.voxelsPerSide() * layer.voxelsPerSide();
  const size_t tsdf_voxels = layer.numBlocks() * vpb;
  const size_t label_voxels = map->mainLabelBlocks().size() * vpb;
  const double bytes = double(tsdf_voxels) * sizeof(tsdf::TsdfVoxel) +
                       double(label_voxels) * sizeof(gsm::LabelVoxel);
  std::printf("  %zu segments in, %zu raw segments out; map: %zu TSDF blocks, %zu label blocks, "
              "%.1f MB, %.1f B per allocated voxel (TSDF %zu B + labels %zu B where labelled)\n\n",
              segments, extracted, layer.numBlocks(), map->mainLabelBlocks().size(), bytes / 1e6,
              bytes / double(std::max<size_t>(1, tsdf_voxels)), sizeof(tsdf::TsdfVoxel),
              sizeof(gsm::LabelVoxel));
}

double peakRssMb() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return double(usage.ru_maxrss) / 1024.0;
}

// Through an in-process server: one Ingest stream, acknowledged frames per second.
void runServer(const Sequence& seq, const Params& params, size_t n_frames,
               const std::string& db) {
  for (const char* suffix : {"", "-wal", "-shm", "-journal"}) std::filesystem::remove(db + suffix);
  ServerOptions options;
  options.listen_address = "127.0.0.1:0";
  options.db_path = db;
  options.params = params;
  auto srv = ObjdbServer::start(options);
  if (!srv.ok()) die("cannot start the server: " + std::string(srv.status().message()));
  grpc::ChannelArguments args;
  args.SetMaxReceiveMessageSize(64 << 20);
  auto stub = v1::ObjectDatabase::NewStub(
      grpc::CreateCustomChannel((*srv)->address(), grpc::InsecureChannelCredentials(), args));
  const double rss_before = peakRssMb();

  grpc::ClientContext context;
  auto stream = stub->Ingest(&context);
  size_t acked = 0, rejected = 0, segment_events = 0;
  Clock::time_point last_ack;
  v1::SessionSummary summary;
  const auto start = Clock::now();
  std::thread reader([&] {
    v1::IngestResponse response;
    while (stream->Read(&response)) {
      if (response.has_ack()) {
        ++acked;
        rejected += response.ack().accepted() ? 0 : 1;
        last_ack = Clock::now();
      } else if (response.has_segment()) {
        ++segment_events;
      } else if (response.has_summary()) {
        summary = response.summary();
      }
    }
  });
  v1::IngestRequest request;
  v1::SessionHeader& header = *request.mutable_header();
  header.set_session_name("frame_bench");
  *header.mutable_intrinsics() = server::toProto(seq.intrinsics);
  header.set_client_info("frame_bench");
  bool open = stream->Write(request);
  const size_t n = seq.frames.size();
  for (size_t i = 0; open && i < n_frames; ++i) {
    // Forward, then back: the camera path stays continuous.
    const size_t round = i / n, k = i % n;
    request.Clear();
    v1::Frame& f = *request.mutable_frame();
    f = seq.frames[round % 2 == 0 ? k : n - 1 - k];
    f.set_index(i);
    f.set_timestamp_s(double(i) / 30.0);
    open = stream->Write(request);
  }
  stream->WritesDone();
  reader.join();
  const auto summary_at = Clock::now();
  const grpc::Status status = stream->Finish();
  if (!status.ok()) die("Ingest: " + status.error_message());
  const double ack_s = std::chrono::duration<double>(last_ack - start).count();
  const double backlog_s = std::chrono::duration<double>(summary_at - last_ack).count();
  grpc::ClientContext end_context;
  v1::EndSessionRequest end;
  end.set_session_name("frame_bench");
  v1::EndSessionResponse ended;
  const auto end_start = Clock::now();
  const grpc::Status end_status = stub->EndSession(&end_context, end, &ended);
  if (!end_status.ok()) die("EndSession: " + end_status.error_message());
  const double end_s = std::chrono::duration<double>(Clock::now() - end_start).count();
  grpc::ClientContext stats_context;
  v1::GetStatsResponse stats;
  const grpc::Status stats_status = stub->GetStats(&stats_context, v1::GetStatsRequest(), &stats);
  if (!stats_status.ok()) die("GetStats: " + stats_status.error_message());
  const auto& c = ended.summary().counters();
  std::printf("server, %s: %zu frames (%zu distinct, forward and back) on one Ingest stream\n",
              seq.name.c_str(), n_frames, n);
  std::printf("  %-44s %10s\n", "figure", "value");
  std::printf("  %-44s %10.1f\n", "acknowledged frames/s", double(acked) / ack_s);
  std::printf("  %-44s %10zu\n", "frames rejected", rejected);
  std::printf("  %-44s %10.2f\n", "last ack -> summary, s (database backlog)", backlog_s);
  std::printf("  %-44s %10.2f\n", "EndSession (flush + final inserts), s", end_s);
  std::printf("  %-44s %10llu\n", "segments into the database",
              (unsigned long long)c.segments_extracted());
  const v1::InsertTimingTotals& it = stats.insert_timings();
  const double db_s = it.total_s();
  std::printf("  %-44s %10.1f\n", "database work per insert, ms",
              it.inserts() > 0 ? 1000.0 * db_s / double(it.inserts()) : 0.0);
  std::printf("  %-44s %10.1f\n", "database work per acknowledged frame, ms",
              acked > 0 ? 1000.0 * db_s / double(acked) : 0.0);
  std::printf("  %-44s %10.0f\n", "peak RSS before the stream, MB", rss_before);
  std::printf("  %-44s %10.0f\n\n", "peak RSS (bench + server), MB", peakRssMb());
  (*srv)->shutdown();
}

}  // namespace
}  // namespace objdb

int main(int argc, char** argv) {
  using namespace objdb;
  bench::setUpBenchmarkProcess();
  std::vector<std::filesystem::path> dirs;
  size_t server_frames = 1000;
  int threads = 2;
  float voxel = 0.02f;
  bool server = true;
  std::string db = (std::filesystem::temp_directory_path() / "frame_bench.sqlite").string();
  int shortlist = -1;  // database.shortlist (< 0: the default)
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--dataset" && i + 1 < argc) {
      dirs.emplace_back(argv[++i]);
    } else if (a == "--server-frames" && i + 1 < argc) {
      server_frames = size_t(std::max(1, std::atoi(argv[++i])));
    } else if (a == "--threads" && i + 1 < argc) {
      threads = std::max(1, std::atoi(argv[++i]));
    } else if (a == "--voxel-size" && i + 1 < argc) {
      voxel = float(std::atof(argv[++i]));
    } else if (a == "--no-server") {
      server = false;
    } else if (a == "--db" && i + 1 < argc) {
      db = argv[++i];
    } else if (a == "--shortlist" && i + 1 < argc) {
      shortlist = std::atoi(argv[++i]);
    } else {
      std::fprintf(stderr,
                   "usage: frame_bench [--dataset DIR]... [--server-frames N] [--threads N] "
                   "[--voxel-size M] [--no-server] [--db FILE] [--shortlist N]\n");
      return 2;
    }
  }
  if (dirs.empty()) {
    for (const char* d : {"../shared/data/sun3d-studyroom/fragment-1",
                          "../shared/data/sun3d-studyroom/fragment-2",
                          "../shared/data/desk-box-realsense"}) {
      if (std::filesystem::exists(d)) dirs.emplace_back(d);
    }
  }
  Params params;
  params.tsdf.voxel_size_m = voxel;
  if (shortlist >= 0) params.database.shortlist = shortlist;  // 0: the vote over every model
  if (Status ok = params.validate(); !ok.ok()) die(std::string(ok.message()));
  std::vector<Sequence> sequences;
  for (const auto& d : dirs) sequences.push_back(loadDataset(d));
  if (sequences.empty()) {
    std::printf("(no real dataset given or found in ../shared/data: the synthetic lounge)\n");
    sequences.push_back(renderLounge(100));
  }
  for (const Sequence& seq : sequences) runOffline(seq, params, threads);
  if (server) runServer(sequences.front(), params, server_frames, db);
  return 0;
}
