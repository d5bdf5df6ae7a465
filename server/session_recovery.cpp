// Ending, at start, the sessions a stopped server left open (RELIABILITY.md R2): each open
// session is marked interrupted; one with a saved map is ended from it on the database thread
// (its segments inserted, its scene stored), while the server already serves.
#include <cmath>

#include "absl/strings/str_format.h"
#include "core/common/logging.h"
#include "core/common/params_io.h"
#include "core/database/object_database.h"
#include "server/job_queue.h"
#include "server/object_database_service.h"
#include "server/session/live_session.h"

namespace objdb::server {

Status ObjectDatabaseService::startRecovery() {
  std::vector<storage::SessionInfo> unended;
  unended.swap(unended_);
  // Those with a saved map are ended from it (on the database thread, while the server serves);
  // the others lost their maps. At the first store error nothing more is written.
  std::vector<storage::SessionInfo> queued;
  Status status = absl::OkStatus();
  for (const auto& s : unended) {
    auto saved_frames = store_->savedMapFrames(s.name);
    status = saved_frames.status();
    if (status.ok() && s.state == storage::SessionState::kOpen) {
      if (*saved_frames < 0) {
        logger("server")->warn("session {} was still open when the server last stopped and has "
                               "no saved map; its map is lost (segments inserted before stay): "
                               "marking it interrupted",
                               s.name);
      }
      // Interrupted at once (it streams no more), whatever its recovery below does.
      status = store_->finishSession(s.name, storage::SessionState::kInterrupted, s.frames);
    }
    if (!status.ok()) {
      status = annotate(status, absl::StrFormat("session %s", s.name));
      queued.clear();
      break;
    }
    if (*saved_frames >= 0) queued.push_back(s);
  }
  {
    std::lock_guard lock(mutex_);
    for (const auto& s : unended) recovering_.erase(s.name);
    for (const auto& s : queued) recovering_.insert(s.name);
  }
  for (const auto& s : queued) {
    database_queue_->push([this, s] {
      const Status recovered = recoverSession(s);
      if (!recovered.ok()) {
        logger("server")->error("session {} could not be ended from its saved map (tried again "
                                "at the next start): {}",
                                s.name, std::string(recovered.message()));
      }
      std::lock_guard lock(mutex_);
      recovering_.erase(s.name);
    });
  }
  return status;
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
      if (absl::IsFailedPrecondition(report.status()) ||
          absl::IsInvalidArgument(report.status())) {
        continue;  // a segment the database cannot take (no surface at the mesh weight)
      }
      return annotate(report.status(), absl::StrFormat("inserting segment %d of session %s",
                                                       segment.label, stored.name));
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
