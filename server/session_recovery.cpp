// Ending the sessions a stopped server left open (docs/server.md): at start, this server's
// own from before; later, those of another server on the same database whose lease expired.
// Each open session is marked interrupted; one with a saved map is ended from it on the database
// thread (its segments inserted, its scene stored), while the server already serves. The lease
// keeper renews this server's session leases, and gives up the sessions whose lease it lost.
#include <cmath>

#include "absl/strings/str_format.h"
#include "core/common/logging.h"
#include "core/common/params_io.h"
#include "core/database/object_database.h"
#include "server/job_queue.h"
#include "server/object_database_service.h"
#include "server/ingest_stream.h"
#include "server/session/live_session.h"

namespace objdb::server {

Status ObjectDatabaseService::startRecovery() {
  std::vector<storage::SessionInfo> unended;
  unended.swap(unended_);
  const Status status = takeOver(unended, /*at_start=*/true);
  {
    std::lock_guard lock(mutex_);
    recovery_started_ = true;
  }
  keeper_wake_.notify_all();
  return status;
}

Status ObjectDatabaseService::takeOver(const std::vector<storage::SessionInfo>& unended,
                                       bool at_start) {
  // Those with a saved map are ended from it (on the database thread, while the server serves);
  // the others lost their maps. At the first store error nothing more is written.
  std::vector<storage::SessionInfo> queued;
  Status status = absl::OkStatus();
  for (const auto& listed : unended) {
    auto saved_frames = store_->savedMapFrames(listed.name);
    status = saved_frames.status();
    if (status.ok() && listed.state != storage::SessionState::kOpen && *saved_frames < 0) {
      continue;  // nothing left to do for it
    }
    StatusOr<std::string> holder = status.ok() ? store_->acquireLease(listed.name, server_id_,
                                                                      options_.lease_ttl)
                                               : StatusOr<std::string>(status);
    status = holder.status();
    if (status.ok() && *holder != server_id_) {
      logger("server")->info("session {} is not ended and server {} holds its lease: left to it",
                             listed.name, *holder);
      continue;
    }
    if (status.ok()) {
      std::lock_guard lock(mutex_);
      leased_.insert(listed.name);
    }
    // Under the lease, the session as it is now: its server may have ended it since the list
    // was read (and then given its lease up).
    storage::SessionInfo s = listed;
    if (status.ok()) {
      auto now = sessionNamed(listed.name);
      status = now.status();
      if (status.ok()) s = *now;
    }
    if (status.ok()) {
      saved_frames = store_->savedMapFrames(s.name);
      status = saved_frames.status();
    }
    const bool open = s.state == storage::SessionState::kOpen;
    if (status.ok() && (s.state == storage::SessionState::kEnded || (!open && *saved_frames < 0))) {
      releaseLease(s.name);
      continue;
    }
    if (status.ok() && *saved_frames >= 0) {
      // Queries of it wait (UNAVAILABLE) until it is ended from its saved map.
      std::lock_guard lock(mutex_);
      recovering_.insert(s.name);
    }
    if (status.ok() && open) {
      if (*saved_frames < 0) {
        logger("server")->warn("session {} was still open when its server stopped and has no "
                               "saved map; its map is lost (segments inserted before stay): "
                               "marking it interrupted",
                               s.name);
      }
      // Interrupted at once (it streams no more), whatever its recovery below does.
      status = store_->finishSession(s.name, storage::SessionState::kInterrupted, s.frames);
    }
    if (!status.ok()) {
      status = annotate(status, absl::StrFormat("session %s", s.name));
      queued.push_back(s);
      {
        std::lock_guard lock(mutex_);
        for (const auto& q : queued) recovering_.erase(q.name);
      }
      for (const auto& q : queued) releaseLease(q.name);
      queued.clear();
      break;
    }
    if (!at_start) sessions_taken_over_.fetch_add(1);
    if (*saved_frames >= 0) {
      queued.push_back(s);
    } else {
      releaseLease(s.name);
    }
  }
  {
    std::lock_guard lock(mutex_);
    if (at_start) {  // announced by create(): those not queued are not being recovered
      for (const auto& s : unended) recovering_.erase(s.name);
    }
    for (const auto& s : queued) recovering_.insert(s.name);
  }
  for (const auto& s : queued) {
    if (!at_start) {
      logger("server")->warn("session {}: its server stopped renewing its lease; taking it over",
                             s.name);
    }
    std::unique_lock lock(mutex_);
    if (keeper_stop_) {  // the server is stopping: left to the next server
      recovering_.erase(s.name);
      lock.unlock();
      releaseLease(s.name);
      continue;
    }
    database_queue_->push([this, s] {
      const Status recovered = recoverSession(s);
      if (!recovered.ok()) {
        logger("server")->error("session {} could not be ended from its saved map (tried again "
                                "at the next start): {}",
                                s.name, std::string(recovered.message()));
      }
      {
        std::lock_guard lock(mutex_);
        recovering_.erase(s.name);
      }
      releaseLease(s.name);
    });
  }
  return status;
}

StatusOr<storage::SessionInfo> ObjectDatabaseService::sessionNamed(const std::string& name) {
  OBJDB_ASSIGN_OR_RETURN(const std::vector<storage::SessionInfo> stored, store_->sessions());
  for (const auto& s : stored) {
    if (s.name == name) return s;
  }
  return absl::NotFoundError(absl::StrFormat("no session %s", name));
}

Status ObjectDatabaseService::leaseNewSession(const std::string& name) {
  {
    std::lock_guard lock(mutex_);
    if (leased_.count(name) != 0 || sessions_.count(name) != 0 || recovering_.count(name) != 0) {
      return absl::AlreadyExistsError(absl::StrFormat("session %s already exists", name));
    }
  }
  OBJDB_ASSIGN_OR_RETURN(const std::string holder,
                         store_->acquireLease(name, server_id_, options_.lease_ttl));
  if (holder != server_id_) {
    return absl::AlreadyExistsError(absl::StrFormat(
        "session %s already exists: server %s streams it (or ends it)", name, holder));
  }
  std::lock_guard lock(mutex_);
  if (!leased_.insert(name).second) {  // a second header of this name, at the same time
    return absl::AlreadyExistsError(absl::StrFormat("session %s already exists", name));
  }
  return absl::OkStatus();
}

Status ObjectDatabaseService::lostLease(const std::string& name) {
  return absl::AbortedError(absl::StrFormat(
      "session %s: this server lost its lease (the database was unreachable for longer than the "
      "lease's time to live); another server may have taken it over, so nothing more of it is "
      "written here",
      name));
}

void ObjectDatabaseService::releaseLease(const std::string& name) {
  {
    std::lock_guard lock(mutex_);
    if (leased_.erase(name) == 0) return;
  }
  if (Status released = store_->releaseLease(name, server_id_); !released.ok()) {
    // It expires on its own; until then no other server takes the session over.
    logger("server")->warn("session {}: could not give up its lease: {}", name,
                           std::string(released.message()));
  }
}

void ObjectDatabaseService::keepLeases() {
  const auto period = std::max<std::chrono::milliseconds>(std::chrono::milliseconds(20),
                                                          options_.lease_ttl / 3);
  // Whether other servers are at work is asked more often than leases are renewed (at least
  // every second), so that live maps are published soon after another server starts a session.
  const auto look = std::min<std::chrono::milliseconds>(period, std::chrono::seconds(1));
  auto renewed_at = std::chrono::steady_clock::now();
  auto kept_at = renewed_at;
  std::unique_lock lock(mutex_);
  while (!keeper_stop_) {
    keeper_wake_.wait_for(lock, look);
    if (keeper_stop_) break;
    // Once stopping, leases are still renewed (stop() ends the sessions), but none taken over.
    const bool takeovers = recovery_started_ && !stopped_;
    const std::set<std::string> leased = leased_;
    lock.unlock();
    if (store_->sharedByServers()) updatePublication();
    if (std::chrono::steady_clock::now() - kept_at < period) {
      lock.lock();
      continue;
    }
    kept_at = std::chrono::steady_clock::now();
    // Renewal first: a lease that lapsed (the database was unreachable for a whole time to live)
    // may be another server's by now.
    std::vector<std::string> lost;
    auto held = store_->renewLeases(server_id_, options_.lease_ttl);
    const auto now = std::chrono::steady_clock::now();
    if (held.ok()) {
      renewed_at = now;
      const std::set<std::string> kept(held->begin(), held->end());
      for (const auto& name : leased) {
        if (kept.count(name) == 0) lost.push_back(name);
      }
    } else {
      logger("server")->warn("session leases could not be renewed: {}",
                             std::string(held.status().message()));
      if (now - renewed_at >= options_.lease_ttl) lost.assign(leased.begin(), leased.end());
    }
    if (!lost.empty()) leasesLost(lost);
    // Open sessions no server renews the lease of: their server stopped.
    std::vector<storage::SessionInfo> orphans;
    if (takeovers && held.ok()) {
      auto stored = store_->sessions();
      if (stored.ok()) {
        std::lock_guard guard(mutex_);
        for (const auto& s : *stored) {
          if (s.state == storage::SessionState::kOpen && sessions_.count(s.name) == 0 &&
              leased_.count(s.name) == 0 && recovering_.count(s.name) == 0) {
            orphans.push_back(s);
          }
        }
      }
    }
    if (!orphans.empty()) {
      if (Status taken = takeOver(orphans, /*at_start=*/false); !taken.ok()) {
        logger("server")->warn("taking over sessions of a stopped server: {}",
                               std::string(taken.message()));
      }
    }
    lock.lock();
  }
}

void ObjectDatabaseService::updatePublication() {
  const auto others = store_->othersHoldLeases(server_id_);
  if (!others.ok()) return;  // as it was (the renewal logs the database's trouble)
  if (publish_maps_.exchange(*others) == *others) return;
  if (!*others) {
    logger("server")->info("no other server holds a session lease: live maps are no longer "
                           "published");
    return;
  }
  logger("server")->info("another server holds a session lease: live maps are published for its "
                         "scene checks, each live session's at once");
  std::lock_guard lock(mutex_);
  for (auto& [name, session] : sessions_) {
    std::lock_guard session_lock(session->mutex);
    if (session->state == v1::SESSION_STATE_ENDED || session->end_queued) continue;
    if (session->streaming) {
      session->publish_requested = true;  // its frame worker saves it at the next frame
    } else if (!session->map_save_pending) {
      session->map_save_pending = true;  // the map is the database thread's
      database_queue_->push([this, session = session] { saveIdleMap(session); });
    } else {
      session->publish_requested = true;  // the janitor saves it once the pending save is done
    }
  }
}

void ObjectDatabaseService::leasesLost(const std::vector<std::string>& lost) {
  for (const auto& name : lost) {
    leases_lost_.fetch_add(1);
    std::shared_ptr<LiveSession> session;
    {
      std::lock_guard lock(mutex_);
      leased_.erase(name);
      if (const auto it = sessions_.find(name); it != sessions_.end()) session = it->second;
    }
    logger("server")->error("session {}: this server lost its lease (not renewed in time; another "
                            "server may take the session over): it writes nothing more of it",
                            name);
    if (session == nullptr) continue;
    std::shared_ptr<IngestStream> stream;
    {
      std::lock_guard lock(session->mutex);
      session->lease_lost = true;
      stream = session->stream.lock();
    }
    if (stream != nullptr) {
      std::lock_guard lock(stream->mutex);
      stream->cancelled = true;
      stream->changed.notify_all();
    }
  }
}

Params ObjectDatabaseService::storedSessionParams(const storage::SessionInfo& stored) const {
  Params params = options_.params;
  if (Status applied = applyParamsJson(stored.params_json, &params); !applied.ok()) {
    params = options_.params;
  }
  return params;
}

Status ObjectDatabaseService::recoveryFailed(const std::string& name, int64_t saved_frames) {
  return absl::FailedPreconditionError(absl::StrFormat(
      "session %s was not ended before the server stopped; ending it from its map saved after %d "
      "frames failed at this start (the server's log says why); the next start tries again",
      name, saved_frames));
}

Status ObjectDatabaseService::checkNotRecovering(const std::string& name) {
  std::lock_guard lock(mutex_);
  if (recovering_.count(name) == 0) return absl::OkStatus();
  return absl::UnavailableError(absl::StrFormat(
      "session %s was not ended before the server stopped and is being ended from its saved map; "
      "try again shortly",
      name));
}

Status ObjectDatabaseService::recoverSession(const storage::SessionInfo& stored) {
  OBJDB_ASSIGN_OR_RETURN(const storage::SavedMap saved, store_->savedMap(stored.name));
  if (saved.map == nullptr) return absl::OkStatus();
  const Params params = storedSessionParams(stored);
  logger("server")->warn("session {} was not ended when the server last stopped: ending it from "
                         "its map saved after {} frames (the frames after it are lost)",
                         stored.name, saved.frames);
  const gsm::LabelBlocks no_labels;
  const std::vector<gsm::RawSegment> segments = gsm::extractLabelled(
      *saved.map, saved.labels ? *saved.labels : no_labels, params.gsm,
      int(std::ceil(params.tsdf.truncation_voxels)), saved.frames);
  size_t inserted = 0, unchanged = 0;
  for (const gsm::RawSegment& segment : segments) {
    // A label extracted (and inserted) before the save and not changed since is already there.
    auto earlier = store_->rawSegment({stored.name, segment.label});
    if (earlier.ok() && sameSegment(**earlier, segment)) {
      ++unchanged;
      continue;
    }
    if (!earlier.ok() && !absl::IsNotFound(earlier.status())) return earlier.status();
    // Its scene is not stored yet: the saved map is what its poses are verified against.
    auto report = db_->insertSegment(
        stored.name, segment,
        [&](const std::string& name) -> std::shared_ptr<const tsdf::TsdfLayer> {
          return name == stored.name ? saved.map : nullptr;
        });
    if (!report.ok()) {
      insert_errors_.fetch_add(1);
      return annotate(report.status(), absl::StrFormat("inserting segment %d of session %s",
                                                       segment.label, stored.name));
    }
    if (report->unusable) {
      segments_unusable_.fetch_add(1);  // stored, held by no model
      continue;
    }
    ++inserted;
  }
  OBJDB_RETURN_IF_ERROR(store_->putScene(stored.name, saved.map, saved.labels));
  OBJDB_RETURN_IF_ERROR(
      store_->finishSession(stored.name, storage::SessionState::kInterrupted, saved.frames));
  OBJDB_RETURN_IF_ERROR(store_->dropSavedMap(stored.name));
  logger("server")->info("session {} ended from its saved map: {} frames, {} segments inserted, "
                         "{} unchanged since they were inserted; state interrupted",
                         stored.name, saved.frames, inserted, unchanged);
  return absl::OkStatus();
}

}  // namespace objdb::server
