// Opening an Ingest stream's session (object_database_service.h): a new one, or an existing
// one continued (SessionHeader.IF_EXISTS_RESUME) or started again (IF_EXISTS_REPLACE), and
// forgetting a session that never received a frame.
#include <chrono>
#include <future>
#include <optional>
#include <string>
#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/time/clock.h"
#include "absl/time/time.h"
#include "core/common/logging.h"
#include "core/common/params_io.h"
#include "core/database/object_database.h"
#include "server/ingest_stream.h"
#include "server/job_queue.h"
#include "server/object_database_service.h"
#include "server/proto_convert.h"
#include "server/service_util.h"
#include "server/session/live_session.h"
#include "storage/model_settings.h"

namespace objdb::server {
namespace {

// ALREADY_EXISTS with what the client can do about it.
Status nameTaken(const Status& status, const std::string& name) {
  if (!absl::IsAlreadyExists(status)) return status;
  return absl::AlreadyExistsError(absl::StrFormat(
      "%s; continue it (objdb stream --resume, SessionHeader.if_exists RESUME), stream it again "
      "(--replace, REPLACE), or give this one another name (--session NAME)",
      status.message()));
}

// The name a replaced session's record keeps: NAME.replaced-<UTC time>.
std::string replacedName(const std::string& name) {
  return absl::StrCat(name, ".replaced-",
                      absl::FormatTime("%Y%m%dT%H%M%E3SZ", absl::Now(), absl::UTCTimeZone()));
}

}  // namespace

StatusOr<std::shared_ptr<LiveSession>> ObjectDatabaseService::openSession(
    const v1::SessionHeader& header, const std::shared_ptr<IngestStream>& stream,
    v1::SessionOpened* opened) {
  opened->set_session_name(header.session_name());
  switch (header.if_exists()) {
    case v1::SessionHeader::IF_EXISTS_REFUSE:
      break;
    case v1::SessionHeader::IF_EXISTS_RESUME: {
      bool again = false;
      OBJDB_ASSIGN_OR_RETURN(std::shared_ptr<LiveSession> resumed,
                             resumeSession(header, stream, &again));
      if (again) {
        // Its map is gone with the server that held it: streamed again from its first frame,
        // on a database without its segments (as one uninterrupted stream would find it).
        OBJDB_ASSIGN_OR_RETURN(const std::optional<uint64_t> withdrawn,
                               replaceSession(header.session_name()));
        opened->set_resumed(true);
        opened->set_replaced(true);
        opened->set_segments_withdrawn(withdrawn.value_or(0));
        logger("server")->info("session {} resumed from its first frame: its map was no longer "
                               "in memory ({} segments withdrawn)",
                               header.session_name(), withdrawn.value_or(0));
        break;
      }
      if (resumed == nullptr) break;  // no such session: a new one
      opened->set_resumed(true);
      opened->set_has_frames(resumed->has_frame);
      opened->set_last_frame_index(resumed->last_index);
      *opened->mutable_counters() = resumed->snapshot();
      return resumed;
    }
    case v1::SessionHeader::IF_EXISTS_REPLACE: {
      // Checked before the old session goes.
      OBJDB_RETURN_IF_ERROR(sessionFromHeader(header, options_.params).status());
      OBJDB_ASSIGN_OR_RETURN(const std::optional<uint64_t> withdrawn,
                             replaceSession(header.session_name()));
      opened->set_replaced(withdrawn.has_value());
      opened->set_segments_withdrawn(withdrawn.value_or(0));
      break;
    }
    default:
      return absl::InvalidArgumentError(absl::StrFormat(
          "header.if_exists is %d, not one of REFUSE (0), RESUME (1), REPLACE (2)",
          int(header.if_exists())));
  }
  return beginNewSession(header, stream);
}

StatusOr<std::shared_ptr<LiveSession>> ObjectDatabaseService::resumeSession(
    const v1::SessionHeader& header, const std::shared_ptr<IngestStream>& stream,
    bool* from_first_frame) {
  *from_first_frame = false;
  const std::string& name = header.session_name();
  OBJDB_ASSIGN_OR_RETURN(const std::shared_ptr<LiveSession> wanted,
                         sessionFromHeader(header, options_.params));
  OBJDB_RETURN_IF_ERROR(checkNotRecovering(name));
  std::shared_ptr<LiveSession> session = liveSession(name);
  if (session == nullptr || session->ended()) {
    auto stored = sessionNamed(name);
    if (absl::IsNotFound(stored.status())) return std::shared_ptr<LiveSession>();
    OBJDB_RETURN_IF_ERROR(stored.status());
    if (stored->state == storage::SessionState::kEnded) {
      return absl::FailedPreconditionError(absl::StrFormat(
          "session %s has ended (EndSession, the server's --auto-end-s, or a server stop ended "
          "it), so it cannot take "
          "more frames: stream it again with --replace (SessionHeader.if_exists REPLACE), or "
          "under another name (--session NAME)",
          name));
    }
    // Interrupted (or open, another server's) and its map not here: its server crashed (this
    // start or another server ended it from its saved map). The label histories of its map were
    // not saved, so it continues from its first frame; the same camera and parameters, as any
    // resume.
    if (stored->intrinsics_json != storage::intrinsicsJson(wanted->intrinsics)) {
      return absl::InvalidArgumentError(absl::StrFormat(
          "header.intrinsics differ from session %s's (%s): a resumed session keeps its camera",
          name, stored->intrinsics_json));
    }
    if (stored->params_json != paramsToJson(wanted->params)) {
      return absl::InvalidArgumentError(absl::StrFormat(
          "header.params_json gives other parameters than session %s has: a resumed session "
          "keeps its parameters (send the same --params)",
          name));
    }
    *from_first_frame = true;
    return std::shared_ptr<LiveSession>();
  }
  if (wanted->intrinsics != session->intrinsics) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "header.intrinsics differ from session %s's (%s): a resumed session keeps its camera",
        name, storage::intrinsicsJson(session->intrinsics)));
  }
  if (paramsToJson(wanted->params) != paramsToJson(session->params)) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "header.params_json gives other parameters than session %s has: a resumed session keeps "
        "its parameters (send the same --params)",
        name));
  }
  {
    std::lock_guard lock(session->mutex);
    if (session->lease_lost) return lostLease(name);
    if (session->streaming) {
      return absl::FailedPreconditionError(absl::StrFormat(
          "session %s still has an Ingest stream (another client streams it, or the server has "
          "not yet seen the old stream break: try again in a few seconds)",
          name));
    }
    if (session->end_queued || session->state == v1::SESSION_STATE_ENDED) {
      return absl::FailedPreconditionError(absl::StrFormat(
          "session %s is being ended (EndSession, or the server's --auto-end-s): once it has, "
          "stream it again with --replace or under another --session",
          name));
    }
    session->streaming = true;
    session->state = v1::SESSION_STATE_OPEN;
    session->ended_unix_s = 0.0;
    session->stream = stream;
  }
  // Behind endStreaming's "interrupted" write, which the queue ran or will run first. Waited for:
  // a save of the idle map the janitor queued before (it reads the map on the database thread)
  // must be done before this stream's frame worker writes to the map again; with `streaming`
  // set, the janitor queues no other.
  std::promise<void> reopened;
  database_queue_->push([this, session, &reopened] {
    if (!session->ended() && !session->leaseLost()) {
      (void)store_->finishSession(session->name, storage::SessionState::kOpen,
                                  int64_t(session->snapshot().frames_integrated()));
    }
    reopened.set_value();
  });
  reopened.get_future().wait();
  logger("server")->info("session {} resumed after frame {} ({} frames integrated, client \"{}\")",
                         name, session->last_index, session->snapshot().frames_integrated(),
                         header.client_info());
  return session;
}

StatusOr<std::optional<uint64_t>> ObjectDatabaseService::replaceSession(const std::string& name) {
  OBJDB_RETURN_IF_ERROR(checkNotRecovering(name));
  if (std::shared_ptr<LiveSession> live = liveSession(name)) {
    {
      std::lock_guard lock(live->mutex);
      if (live->streaming) {
        return absl::FailedPreconditionError(absl::StrFormat(
            "session %s still has an Ingest stream: it cannot be replaced until that ends", name));
      }
      if (live->end_queued && live->state != v1::SESSION_STATE_ENDED) {
        return absl::FailedPreconditionError(absl::StrFormat(
            "session %s is being ended (EndSession, or the server's --auto-end-s): replace it "
            "once it has",
            name));
      }
      live->end_queued = true;  // neither the janitor nor the stop ends it any more
    }
    std::lock_guard lock(mutex_);
    sessions_.erase(name);
  }
  auto stored = sessionNamed(name);
  if (absl::IsNotFound(stored.status())) {
    releaseLease(name);
    return std::optional<uint64_t>();
  }
  OBJDB_RETURN_IF_ERROR(stored.status());
  // Another server may stream it (a shared database): then it is that server's.
  OBJDB_ASSIGN_OR_RETURN(const std::string holder,
                         store_->acquireLease(name, server_id_, options_.lease_ttl));
  if (holder != server_id_) {
    return absl::FailedPreconditionError(absl::StrFormat(
        "session %s is streamed (or ended) by server %s: it cannot be replaced here", name,
        holder));
  }
  // On the database thread, after every job of the old session queued before.
  std::promise<StatusOr<uint64_t>> done;
  database_queue_->push([this, &done, name] {
    auto withdraw = [&]() -> StatusOr<uint64_t> {
      OBJDB_ASSIGN_OR_RETURN(const std::vector<database::SegmentKey> keys,
                             store_->rawSegmentKeys());
      uint64_t withdrawn = 0;
      for (const database::SegmentKey& key : keys) {
        if (key.session != name) continue;
        OBJDB_ASSIGN_OR_RETURN(const database::ObjectDatabase::Withdrawal w,
                               db_->withdrawSegment(name, key.label));
        withdrawn += w.model_id != 0 ? 1 : 0;
      }
      const std::string renamed = replacedName(name);
      OBJDB_ASSIGN_OR_RETURN(const bool deleted, store_->retireSession(name, renamed));
      logger("server")->info("session {} replaced: {} segments withdrawn from its models; {}",
                             name, withdrawn,
                             deleted ? std::string("its row deleted")
                                     : absl::StrCat("its record kept as ", renamed));
      return withdrawn;
    };
    done.set_value(withdraw());
  });
  StatusOr<uint64_t> withdrawn = done.get_future().get();
  releaseLease(name);
  OBJDB_RETURN_IF_ERROR(withdrawn.status());
  return std::optional<uint64_t>(*withdrawn);
}

void ObjectDatabaseService::forgetEmptySession(const std::shared_ptr<LiveSession>& session) {
  {
    std::lock_guard lock(session->mutex);
    if (session->counters.frames_received() != 0 || session->streaming || session->end_queued) {
      return;
    }
    session->end_queued = true;  // no resume, no EndSession flush, no janitor
  }
  database_queue_->push([this, session] { retireEmptySession(*session); });
}

void ObjectDatabaseService::retireEmptySession(LiveSession& session) {
  {
    std::lock_guard lock(session.mutex);
    if (session.state == v1::SESSION_STATE_ENDED) return;  // retired already
    session.state = v1::SESSION_STATE_ENDED;
    session.ended_unix_s = nowUnixSeconds();
  }
  session.map.reset();
  session.segmenter.reset();
  {
    std::lock_guard lock(mutex_);
    const auto it = sessions_.find(session.name);
    if (it != sessions_.end() && it->second.get() == &session) sessions_.erase(it);
  }
  // Nothing refers to it (no frame, no segment, no scene): the row goes.
  const auto retired = store_->retireSession(session.name, replacedName(session.name));
  if (!retired.ok()) {
    logger("server")->warn("session {} received no frame, but its row could not be deleted: {}",
                           session.name, std::string(retired.status().message()));
  } else {
    logger("server")->info("session {} received no frame: not kept", session.name);
  }
  releaseLease(session.name);
}

StatusOr<std::shared_ptr<LiveSession>> ObjectDatabaseService::beginNewSession(
    const v1::SessionHeader& header, const std::shared_ptr<IngestStream>& stream) {
  {
    // Refused before a map is built (checked again when the session is published).
    std::lock_guard lock(mutex_);
    OBJDB_RETURN_IF_ERROR(checkSessionLimit());
  }
  OBJDB_ASSIGN_OR_RETURN(std::shared_ptr<LiveSession> session,
                         sessionFromHeader(header, options_.params));
  OBJDB_ASSIGN_OR_RETURN(const std::vector<storage::SessionInfo> stored, store_->sessions());
  // The models of this session must be described as the database's are (and as the server's).
  storage::SessionInfo server_settings;
  server_settings.name = "(the server's --config)";
  server_settings.params_json = paramsToJson(options_.params);
  for (const std::vector<storage::SessionInfo>& against : {stored, {server_settings}}) {
    if (Status same = storage::checkModelSettings(against, session->params); !same.ok()) {
      return absl::InvalidArgumentError(absl::StrCat("header.params_json: ", same.message()));
    }
  }
  OBJDB_RETURN_IF_ERROR(startPipeline(*session, options_.integration_threads));
  if (store_->sharedByServers()) session->publish_scenes = &publish_maps_;
  OBJDB_RETURN_IF_ERROR(nameTaken(leaseNewSession(session->name), session->name));

  {
    // A place under the session limit is taken before the store is written, and the store is
    // written outside the service mutex (the query and callback threads take it too).
    std::unique_lock lock(mutex_);
    Status reserved = stopped_ ? absl::UnavailableError("the server is shutting down")
                               : checkSessionLimit();
    if (!reserved.ok()) {
      lock.unlock();
      releaseLease(session->name);
      return reserved;
    }
    ++opening_;
  }
  storage::SessionInfo info;
  info.name = session->name;
  info.intrinsics_json = storage::intrinsicsJson(session->intrinsics);
  info.params_json = paramsToJson(session->params);
  info.client_info = session->client_info;
  // ALREADY_EXISTS when the database has a session of that name.
  const Status begun = nameTaken(store_->beginSession(info).status(), session->name);
  std::unique_lock lock(mutex_);
  --opening_;
  if (!begun.ok() || stopped_) {
    lock.unlock();
    if (begun.ok()) {
      // Stored as open while the server began to stop, whose sweep of unended sessions did not
      // see it: it ends as interrupted now, with nothing integrated.
      (void)store_->finishSession(session->name, storage::SessionState::kInterrupted, 0);
    }
    releaseLease(session->name);
    return begun.ok() ? absl::UnavailableError("the server is shutting down") : begun;
  }
  session->started_unix_s = nowUnixSeconds();
  session->stream = stream;  // before it is published: EndSession looks at the stream
  sessions_[session->name] = session;
  logger("server")->info("session {} opened ({}x{}, client \"{}\")", session->name,
                         session->intrinsics.width, session->intrinsics.height,
                         session->client_info);
  return session;
}

}  // namespace objdb::server
