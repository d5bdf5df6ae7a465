// The Ingest call's two sides (server/object_database_service.h): IngestReactor runs on gRPC's
// threads and only moves messages (frames into the inbox, events out of the outbox); the
// session's frame worker takes frames from the inbox and sends events through IngestStream. One
// stream is one session; backpressure: reads pause while frame_queue frames wait, and a client
// that reads none of max_pending events is ended after a timeout (waitForReader).
#pragma once

#include <chrono>
#include <condition_variable>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>

#include <grpcpp/grpcpp.h>

#include "objdb/v1/objdb.grpc.pb.h"

namespace objdb::server {

class IngestReactor;
struct LiveSession;

// What the reactor (gRPC threads) and the frame worker share. Reactor calls happen under the
// mutex and only while `reactor` is set (OnDone clears it).
struct IngestStream {
  std::recursive_mutex mutex;
  std::condition_variable_any changed;
  IngestReactor* reactor = nullptr;
  bool header_seen = false;
  v1::SessionHeader header;               // the first message, handed to the frame worker
  std::shared_ptr<LiveSession> session;   // set by the frame worker once the session is open
  std::deque<v1::Frame> inbox;
  bool reads_paused = false;
  bool input_ended = false;  // the client half-closed
  bool cancelled = false;    // cancelled, or ended by an error: stop working
  bool finished = false;     // Finish was called (or is pending behind writes)
  std::deque<v1::IngestResponse> outbox;
  bool writing = false;
  std::chrono::steady_clock::time_point last_write_done{};  // the client's last read (progress)
  std::optional<grpc::Status> finish_pending;

  void send(v1::IngestResponse response);
  // Frame worker, before each frame: waits while `max_pending` events wait for the client. False
  // when the stream was cancelled or finished meanwhile, or when the client read nothing for
  // `timeout` (counted from the later of the wait's start and its last read): then the stream is
  // finished with RESOURCE_EXHAUSTED (delivered after the event being written, whenever the
  // client reads again), and the events behind that one and the frames not yet taken are dropped.
  bool waitForReader(size_t max_pending, std::chrono::milliseconds timeout,
                     const std::string& session);
  void finish(const grpc::Status& status);
  void resumeReading();
};

class IngestReactor final : public grpc::ServerBidiReactor<v1::IngestRequest, v1::IngestResponse> {
 public:
  // `start_worker` runs the stream's frame worker once the header came (on a thread of its own);
  // at most `frame_queue` frames wait in the inbox before reading pauses.
  using StartWorker = std::function<void(std::shared_ptr<IngestStream>)>;
  IngestReactor(grpc::CallbackServerContext* context, size_t frame_queue, StartWorker start_worker)
      : context_(context),
        frame_queue_(frame_queue),
        start_worker_(std::move(start_worker)),
        stream_(std::make_shared<IngestStream>()) {
    stream_->reactor = this;
    StartRead(&request_);
  }

  void OnReadDone(bool ok) override {
    // The frame worker starts outside the stream's mutex: startWorker takes the service's mutex,
    // which the janitor holds while it takes a session's, and EndSession takes a stream's mutex
    // while it holds a session's (one lock order: service, session, stream).
    if (takeRead(ok)) start_worker_(stream_);
  }

  void OnWriteDone(bool ok) override {
    std::lock_guard lock(stream_->mutex);
    stream_->outbox.pop_front();
    stream_->last_write_done = std::chrono::steady_clock::now();
    stream_->changed.notify_all();  // a frame worker may wait for room (waitForReader)
    if (!ok) {  // the client is gone
      stream_->outbox.clear();
      stream_->cancelled = true;
      stream_->changed.notify_all();
    }
    if (!stream_->outbox.empty()) {
      StartWrite(&stream_->outbox.front());
      return;
    }
    stream_->writing = false;
    if (stream_->finish_pending) {
      Finish(*stream_->finish_pending);
      stream_->finish_pending.reset();
    }
  }

  void OnCancel() override {
    std::lock_guard lock(stream_->mutex);
    stream_->cancelled = true;
    // Without a header there is no worker to end the call: gRPC needs Finish even when cancelled.
    if (!stream_->header_seen) stream_->finish(grpc::Status(grpc::StatusCode::CANCELLED, "cancelled"));
    stream_->changed.notify_all();
  }

  void OnDone() override {
    {
      std::lock_guard lock(stream_->mutex);
      stream_->reactor = nullptr;
      stream_->cancelled = true;
      stream_->changed.notify_all();
    }
    delete this;
  }

  void read() { StartRead(&request_); }

 private:
  // The read's effect on the stream, under its mutex; true when the header came and the frame
  // worker is to be started.
  bool takeRead(bool ok) {
    std::lock_guard lock(stream_->mutex);
    if (stream_->finished) return false;
    if (!ok || stream_->cancelled) {
      if (!stream_->header_seen) {  // no worker to end the call: end it here
        stream_->finish(stream_->cancelled || context_->IsCancelled()
                            ? grpc::Status(grpc::StatusCode::CANCELLED, "cancelled")
                            : grpc::Status(grpc::StatusCode::FAILED_PRECONDITION,
                                           "the stream ended before its SessionHeader"));
      } else if (!ok && context_->IsCancelled()) {
        stream_->cancelled = true;
      } else if (!ok) {
        stream_->input_ended = true;
      }
      stream_->changed.notify_all();
      return false;
    }
    if (!stream_->header_seen) {
      if (!request_.has_header()) {
        stream_->finish(grpc::Status(grpc::StatusCode::FAILED_PRECONDITION,
                                     "the first message of an Ingest stream must be a "
                                     "SessionHeader; a frame came first"));
        return false;
      }
      // The frame worker opens the session (checks, store write): no waiting on gRPC's threads.
      stream_->header_seen = true;
      stream_->header = request_.header();
      StartRead(&request_);
      return true;
    }
    if (request_.has_header()) {
      stream_->cancelled = true;
      stream_->finish(grpc::Status(grpc::StatusCode::FAILED_PRECONDITION,
                                   "a second SessionHeader on the stream of session " +
                                       stream_->header.session_name() +
                                       "; one stream is one session"));
      stream_->changed.notify_all();
      return false;
    }
    stream_->inbox.push_back(std::move(*request_.mutable_frame()));
    stream_->changed.notify_all();
    if (stream_->inbox.size() < frame_queue_) {
      StartRead(&request_);
    } else {
      stream_->reads_paused = true;  // the worker resumes reading when it takes a frame
    }
    return false;
  }

  grpc::CallbackServerContext* context_;
  const size_t frame_queue_;
  const StartWorker start_worker_;
  std::shared_ptr<IngestStream> stream_;
  v1::IngestRequest request_;
};

}  // namespace objdb::server
