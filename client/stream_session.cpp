#include "client/stream_session.h"

#include <cstdio>
#include <mutex>
#include <thread>

#include "client/cli_util.h"
#include "client/progress.h"
#include "server/proto_convert.h"

namespace objdb::cli {

int streamSession(v1::ObjectDatabase::Stub& stub, const std::string& name, const io::Dataset& ds,
                  const StreamOptions& options, const char* command) {
  grpc::ClientContext context;
  auto stream = stub.Ingest(&context);
  const size_t frames = (ds.size() + size_t(options.every) - 1) / size_t(options.every);
  std::printf("session %s: %zu frames from %s to %s\n", name.c_str(), frames,
              ds.root().c_str(), options.connection.server.c_str());

  // The reader: acks drive the progress bar; rejections and (with -v) events are printed.
  std::mutex print_mutex;
  size_t acked = 0, rejected = 0, segments = 0, created = 0, merged = 0, joined = 0, removed = 0;
  v1::SessionSummary summary;
  ProgressBar bar("  segmenting, fusing, inserting on the server", frames);
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
          if (response.object().kind() == v1::ObjectEvent::REMOVED) {
            ++removed;
            if (options.verbose) {
              std::printf("  object %llu removed (its only segment was re-extracted or withdrawn"
                          "; now in object %llu)\n",
                          (unsigned long long)response.object().object_id(),
                          (unsigned long long)response.object().into_object_id());
            }
          } else if (response.object().kind() == v1::ObjectEvent::MERGED &&
              response.object().object_id() != 0) {
            ++joined;
            if (options.verbose) {
              std::printf("  object %llu merged into object %llu (both took the segment; e_TSDF "
                          "%.4f m, o_TSDF %llu)\n",
                          (unsigned long long)response.object().object_id(),
                          (unsigned long long)response.object().into_object_id(),
                          response.object().evidence().tsdf_rmse_m(),
                          (unsigned long long)response.object().evidence().overlap_voxels());
            }
          } else if (response.object().kind() == v1::ObjectEvent::MERGED) {
            ++merged;
            if (options.verbose) {
              const v1::MergeEvidence& e = response.object().evidence();
              std::printf(" merged into object %llu (e_TSDF %.4f m, o_TSDF %llu, colour %.3f over "
                          "%llu voxels%s)\n",
                          (unsigned long long)response.object().into_object_id(), e.tsdf_rmse_m(),
                          (unsigned long long)e.overlap_voxels(), e.colour_distance(),
                          (unsigned long long)e.colour_pairs(),
                          e.loosened() ? "; beyond 2 cm, within the measured depth noise" : "");
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
  if (!load_error.ok()) return reportError(command, load_error);
  if (!status.ok()) return reportRpcError(command, "Ingest of session " + name, options.connection.server, status);
  std::printf("  %zu frames acked (%zu rejected), %zu segments into the database (%zu new objects, "
              "%zu merged into earlier ones; %zu objects merged into others, %zu removed)\n",
              acked, rejected, segments, created, merged, joined, removed);
  if (!options.end) {
    std::printf("  session %s left open (--no-end)\n", name.c_str());
    return 0;
  }
  grpc::ClientContext end_context;
  setDeadline(&end_context, options.end_timeout_s);
  v1::EndSessionRequest end;
  end.set_session_name(name);
  v1::EndSessionResponse ended;
  const grpc::Status end_status = stub.EndSession(&end_context, end, &ended);
  if (!end_status.ok()) {
    return reportRpcError(command, "EndSession of " + name, options.connection.server, end_status);
  }
  const v1::SessionCounters& c = ended.summary().counters();
  std::printf("  ended: %llu frames integrated, %llu segments (%llu new objects, %llu merges, "
              "%llu withdrawn, %llu objects joined others); %d objects observed in the session\n",
              (unsigned long long)c.frames_integrated(), (unsigned long long)c.segments_extracted(),
              (unsigned long long)c.objects_created(), (unsigned long long)c.objects_merged(),
              (unsigned long long)c.segments_withdrawn(), (unsigned long long)c.objects_joined(),
              ended.summary().object_ids_size());
  return 0;
}


}  // namespace objdb::cli
