#include "server/ingest_stream.h"

#include <algorithm>

#include "absl/strings/str_format.h"
#include "core/common/logging.h"

namespace objdb::server {

void IngestStream::send(v1::IngestResponse response) {
  std::lock_guard lock(mutex);
  if (reactor == nullptr || finished) return;
  outbox.push_back(std::move(response));
  if (!writing) {
    writing = true;
    reactor->StartWrite(&outbox.front());
  }
}

bool IngestStream::waitForReader(size_t max_pending, std::chrono::milliseconds timeout,
                                 const std::string& session) {
  std::unique_lock lock(mutex);
  const auto room = [&] { return cancelled || finished || outbox.size() < max_pending; };
  // The timeout runs from the later of the wait's start and the client's last read.
  const auto waiting_since = std::chrono::steady_clock::now();
  const auto give_up = [&] { return std::max(waiting_since, last_write_done) + timeout; };
  while (!room()) {
    if (changed.wait_until(lock, give_up(), room)) break;
    if (give_up() > std::chrono::steady_clock::now()) continue;  // the client read meanwhile
    const size_t pending = outbox.size();
    // The front event is being written (gRPC holds it); the others are never sent, and the
    // frames not yet taken are never fused.
    if (writing && pending > 1) outbox.erase(outbox.begin() + 1, outbox.end());
    inbox.clear();
    cancelled = true;
    const double seconds = std::chrono::duration<double>(timeout).count();
    finish(grpc::Status(
        grpc::StatusCode::RESOURCE_EXHAUSTED,
        absl::StrFormat("the client read none of the %d events waiting on the Ingest stream of "
                        "session %s for %g s; stream ended (the session is kept, "
                        "interrupted: EndSession stores it)",
                        pending, session, seconds)));
    changed.notify_all();
    logger("server")->warn("session {}: the client has read none of its {} waiting events for "
                           "{} s; ending its stream",
                           session, pending, seconds);
    return false;
  }
  return !cancelled && !finished;
}

void IngestStream::finish(const grpc::Status& status) {
  std::lock_guard lock(mutex);
  if (reactor == nullptr || finished) return;
  finished = true;
  if (writing) {
    finish_pending = status;
  } else {
    reactor->Finish(status);
  }
}

void IngestStream::resumeReading() {
  std::lock_guard lock(mutex);
  if (reactor == nullptr || finished || !reads_paused) return;
  reads_paused = false;
  reactor->read();
}

// ---------------------------------------------------------------------------------------------
// Service
// ---------------------------------------------------------------------------------------------
}  // namespace objdb::server
