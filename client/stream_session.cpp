#include "client/stream_session.h"

#include <cstdio>
#include <future>
#include <mutex>
#include <optional>
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

  // The reader: the session's first answer (SessionOpened) goes to the writer; acks drive the
  // progress bar (made once the writer knows what it sends); rejections and (with -v) events are
  // printed.
  std::mutex print_mutex;
  size_t acked = 0, rejected = 0, segments = 0, created = 0, merged = 0, joined = 0, removed = 0;
  v1::SessionSummary summary;
  std::optional<ProgressBar> bar;
  std::promise<std::optional<v1::SessionOpened>> opened_promise;
  bool opened_told = false;
  std::thread reader([&] {
    v1::IngestResponse response;
    while (stream->Read(&response)) {
      std::lock_guard lock(print_mutex);
      switch (response.event_case()) {
        case v1::IngestResponse::kOpened:
          if (!opened_told) opened_promise.set_value(response.opened());
          opened_told = true;
          break;
        case v1::IngestResponse::kAck:
          ++acked;
          if (!response.ack().accepted()) {
            ++rejected;
            std::fprintf(stderr, "\nobjdb stream: frame %llu rejected: %s\n",
                         (unsigned long long)response.ack().index(),
                         response.ack().reason().c_str());
          }
          if (bar) bar->update(acked);
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
    std::lock_guard lock(print_mutex);
    if (!opened_told) opened_promise.set_value(std::nullopt);  // refused: Finish says why
    opened_told = true;
  });

  v1::IngestRequest request;
  v1::SessionHeader& header = *request.mutable_header();
  header.set_session_name(name);
  *header.mutable_intrinsics() = server::toProto(ds.intrinsics());
  header.set_params_json(options.params_json);
  header.set_client_info("objdb stream");
  header.set_if_exists(options.if_exists);
  bool open = stream->Write(request);
  // The frames the session holds already (resumed) are not sent again.
  const std::optional<v1::SessionOpened> opened =
      open ? opened_promise.get_future().get() : std::nullopt;
  open = open && opened.has_value();
  size_t first = 0;
  if (opened && opened->resumed() && opened->has_frames()) {
    first = size_t(opened->last_frame_index()) + 1;
    first = (first + size_t(options.every) - 1) / size_t(options.every) * size_t(options.every);
    std::printf("  resumed: its map holds %llu frames, up to frame %llu; sending from frame %zu\n",
                (unsigned long long)opened->counters().frames_integrated(),
                (unsigned long long)opened->last_frame_index(), first);
  } else if (opened && opened->resumed() && opened->replaced()) {
    std::printf("  resumed from its first frame: its map was lost (the server crashed since); "
                "%llu of its segments withdrawn, every frame sent again\n",
                (unsigned long long)opened->segments_withdrawn());
  } else if (opened && opened->resumed()) {
    std::printf("  resumed: it holds no frame yet\n");
  } else if (opened && opened->replaced()) {
    std::printf("  replaced the earlier session of this name: %llu of its segments withdrawn\n",
                (unsigned long long)opened->segments_withdrawn());
  }
  {
    std::lock_guard lock(print_mutex);
    const size_t to_send =
        first < ds.size() ? (ds.size() - first + size_t(options.every) - 1) / size_t(options.every)
                          : 0;
    bar.emplace("  segmenting, fusing, inserting on the server", to_send);
  }
  Status load_error = absl::OkStatus();
  size_t failed_frame = 0;
  for (size_t i = first; open && i < ds.size(); i += size_t(options.every)) {
    auto frame = ds.loadFrame(i);
    if (!frame.ok()) {
      load_error = frame.status();
      failed_frame = i;
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
  // Also after a frame that could not be read: the frames sent are fused (nothing sent is lost)
  // and the session stays open, for --resume once the file is fixed.
  stream->WritesDone();
  reader.join();
  const grpc::Status status = stream->Finish();
  if (bar) bar->finish();
  if (!load_error.ok()) {
    const int rc = reportError(command, load_error);
    std::fprintf(stderr,
                 "objdb %s: session %s stops before frame %zu, open on the server with the "
                 "frames before it (until EndSession or the server's --auto-end-s); once the "
                 "file is fixed, the same command with --resume continues it from there, or "
                 "--replace streams it again\n",
                 command, name.c_str(), failed_frame);
    return rc;
  }
  if (!status.ok()) return reportRpcError(command, "Ingest of session " + name, options.connection.server, status);
  std::printf("  %s acked (%zu rejected), %s into the database (%s, %zu merged into earlier "
              "ones; %s merged into others, %zu removed)\n",
              counted(acked, "frame").c_str(), rejected, counted(segments, "segment").c_str(),
              counted(created, "new object").c_str(), merged,
              counted(joined, "object").c_str(), removed);
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
  std::printf("  ended: %s integrated, %s (%s, %s, %llu withdrawn, %s joined others); %s "
              "observed in the session\n",
              counted(c.frames_integrated(), "frame").c_str(),
              counted(c.segments_extracted(), "segment").c_str(),
              counted(c.objects_created(), "new object").c_str(),
              counted(c.objects_merged(), "merge").c_str(),
              (unsigned long long)c.segments_withdrawn(),
              counted(c.objects_joined(), "object").c_str(),
              counted(uint64_t(ended.summary().object_ids_size()), "object").c_str());
  return 0;
}


}  // namespace objdb::cli
