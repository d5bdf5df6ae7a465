// `objdb stream`: a dataset to an objdb server over gRPC, one Ingest stream per session — the
// on-line counterpart of `objdb ingest`. Frames go out as FLOAT32 depth (metres, exactly what
// the dataset reader produced) with RGB8 colour; a second thread reads the server's acks and
// events while the first writes, so the server's backpressure paces the writer. Then EndSession
// flushes the session's map into the database.
#include <cstdio>
#include <map>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/str_format.h"
#include "client/cli_util.h"
#include "client/commands.h"
#include "client/progress.h"
#include "client/remote.h"
#include "core/io/dataset.h"
#include "core/io/io_util.h"
#include "server/proto_convert.h"

namespace objdb {
namespace {

constexpr const char* kCommand = "stream";

constexpr const char* kUsage = R"(usage: objdb stream [--server HOST:PORT] DATASET... [options]

Streams datasets to an objdb server: each dataset (objdb or TUM layout) is one session, named
after its folder; a folder holding several sessions (the lounge of `objdb sim --preset lounge`)
streams each of them, in name order. The server segments every frame, fuses it into the session's
Global Segmentation Map and inserts extracted segments into its object database; this command
shows its acks and events, then ends the session (EndSession), which stores the session's map.

)" OBJDB_CONNECTION_USAGE R"(  --params FILE        per-session parameter overrides as JSON (segmentation, tsdf, gsm sections)
  --every N            send every N-th frame (default 1)
  --no-end             leave the sessions open (EndSession later, or never)
  --end-timeout S      seconds EndSession may take (default 600)
  -v, --verbose        print every segment and object event
  -h, --help           show this text

exit status: 0 all sessions streamed (rejected frames are reported, not fatal); 1 a call failed;
2 command-line error.
)";

struct Options {
  cli::Connection connection;
  std::string params_json;
  long long every = 1;
  bool end = true;
  double end_timeout_s = 600.0;
  bool verbose = false;
};

// Streams one session; prints its summary. Returns the process exit status.
int streamSession(v1::ObjectDatabase::Stub& stub, const std::string& name, const io::Dataset& ds,
                  const Options& options) {
  grpc::ClientContext context;
  auto stream = stub.Ingest(&context);
  const size_t frames = (ds.size() + size_t(options.every) - 1) / size_t(options.every);
  std::printf("session %s: %zu frames from %s to %s\n", name.c_str(), frames,
              ds.root().c_str(), options.connection.server.c_str());

  // The reader: acks drive the progress bar; rejections and (with -v) events are printed.
  std::mutex print_mutex;
  size_t acked = 0, rejected = 0, segments = 0, created = 0, merged = 0;
  v1::SessionSummary summary;
  cli::ProgressBar bar("  segmenting, fusing, inserting on the server", frames);
  std::thread reader([&] {
    v1::IngestResponse response;
    while (stream->Read(&response)) {
      std::lock_guard lock(print_mutex);
      switch (response.event_case()) {
        case v1::IngestResponse::kAck:
          ++acked;
          if (!response.ack().accepted()) {
            ++rejected;
            std::fprintf(stderr, "\nobjdb stream: frame %llu rejected: %s\n",
                         (unsigned long long)response.ack().index(),
                         response.ack().reason().c_str());
          }
          bar.update(acked);
          break;
        case v1::IngestResponse::kSegment:
          ++segments;
          if (options.verbose) {
            std::printf("\n  segment %llu (label %u, %u voxels)",
                        (unsigned long long)response.segment().segment_id(),
                        response.segment().gsm_label(), response.segment().num_voxels());
          }
          break;
        case v1::IngestResponse::kObject:
          if (response.object().kind() == v1::ObjectEvent::MERGED) {
            ++merged;
            if (options.verbose) {
              std::printf(" merged into object %llu (e_TSDF %.4f m, o_TSDF %llu)\n",
                          (unsigned long long)response.object().into_object_id(),
                          response.object().evidence().tsdf_rmse_m(),
                          (unsigned long long)response.object().evidence().overlap_voxels());
            }
          } else {
            ++created;
            if (options.verbose) {
              std::printf(" became object %llu\n",
                          (unsigned long long)response.object().object_id());
            }
          }
          break;
        case v1::IngestResponse::kSummary:
          summary = response.summary();
          break;
        default:
          break;
      }
    }
  });

  v1::IngestRequest request;
  v1::SessionHeader& header = *request.mutable_header();
  header.set_session_name(name);
  *header.mutable_intrinsics() = server::toProto(ds.intrinsics());
  header.set_params_json(options.params_json);
  header.set_client_info("objdb stream");
  bool open = stream->Write(request);
  Status load_error = absl::OkStatus();
  for (size_t i = 0; open && i < ds.size(); i += size_t(options.every)) {
    auto frame = ds.loadFrame(i);
    if (!frame.ok()) {
      load_error = frame.status();
      break;
    }
    request.Clear();
    v1::Frame& f = *request.mutable_frame();
    f.set_index(i);
    f.set_timestamp_s(frame->timestamp);
    *f.mutable_t_world_camera() = server::toProto(frame->T_world_camera);
    *f.mutable_depth() = server::encodeDepth(frame->depth);
    if (frame->color) *f.mutable_color() = server::encodeColor(*frame->color);
    open = stream->Write(request);
  }
  if (!load_error.ok()) context.TryCancel();
  stream->WritesDone();
  reader.join();
  const grpc::Status status = stream->Finish();
  bar.finish();
  if (!load_error.ok()) return cli::reportError(kCommand, load_error);
  if (!status.ok()) return cli::reportRpcError(kCommand, "Ingest of session " + name, options.connection.server, status);
  std::printf("  %zu frames acked (%zu rejected), %zu segments into the database (%zu new objects, "
              "%zu merged into earlier ones)\n",
              acked, rejected, segments, created, merged);
  if (!options.end) {
    std::printf("  session %s left open (--no-end)\n", name.c_str());
    return 0;
  }
  grpc::ClientContext end_context;
  cli::setDeadline(&end_context, options.end_timeout_s);
  v1::EndSessionRequest end;
  end.set_session_name(name);
  v1::EndSessionResponse ended;
  const grpc::Status end_status = stub.EndSession(&end_context, end, &ended);
  if (!end_status.ok()) {
    return cli::reportRpcError(kCommand, "EndSession of " + name, options.connection.server, end_status);
  }
  const v1::SessionCounters& c = ended.summary().counters();
  std::printf("  ended: %llu frames integrated, %llu segments (%llu new objects, %llu merges); "
              "%d objects observed in the session\n",
              (unsigned long long)c.frames_integrated(), (unsigned long long)c.segments_extracted(),
              (unsigned long long)c.objects_created(), (unsigned long long)c.objects_merged(),
              ended.summary().object_ids_size());
  return 0;
}

}  // namespace

int runStreamCommand(int argc, char** argv) {
  Options options;
  std::string params_file;
  std::vector<std::string> datasets;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "-h" || a == "--help") {
      std::fputs(kUsage, stdout);
      return 0;
    }
    if (a == "-v" || a == "--verbose") {
      options.verbose = true;
      continue;
    }
    if (a == "--no-end") {
      options.end = false;
      continue;
    }
    if (a.rfind("--", 0) != 0) {
      datasets.push_back(a);
      continue;
    }
    if (i + 1 >= argc) return cli::usageError(kCommand, a + " needs a value", kUsage);
    const char* value = argv[++i];
    long long seconds = 0;
    if (cli::takeConnectionFlag(a, value, &options.connection)) {
    } else if (a == "--params") {
      params_file = value;
    } else if (a == "--every") {
      if (!cli::parseInt(value, 1, 1000000, &options.every)) {
        return cli::usageError(kCommand, std::string("--every needs a positive integer, got ") + value, kUsage);
      }
    } else if (a == "--end-timeout") {
      if (!cli::parseInt(value, 1, 86400, &seconds)) {
        return cli::usageError(kCommand, std::string("--end-timeout needs 1..86400 seconds, got ") + value, kUsage);
      }
      options.end_timeout_s = double(seconds);
    } else {
      return cli::usageError(kCommand, "unknown option '" + a + "'", kUsage);
    }
  }
  if (datasets.empty()) return cli::usageError(kCommand, "at least one DATASET is required", kUsage);
  if (options.connection.server.empty()) return cli::usageError(kCommand, "--server is empty", kUsage);
  if (!params_file.empty()) {
    auto text = io::internal::readFile(params_file);
    if (!text.ok()) return cli::reportError(kCommand, text.status());
    options.params_json = *text;
  }
  auto sessions = cli::datasetSessions(datasets);
  if (!sessions.ok()) return cli::reportError(kCommand, sessions.status());
  auto channel = cli::openChannel(options.connection);
  if (!channel.ok()) return cli::reportError(kCommand, channel.status());
  auto stub = v1::ObjectDatabase::NewStub(*channel);
  for (const auto& [name, path] : *sessions) {
    auto opened = io::openDataset(path);
    if (!opened.ok()) return cli::reportError(kCommand, opened.status());
    if (const int rc = streamSession(*stub, name, **opened, options); rc != 0) return rc;
  }
  return 0;
}

}  // namespace objdb
