#include "server/session/published_scenes.h"

#include <chrono>

#include "core/common/logging.h"

namespace objdb::server {
namespace {
double msSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
      .count();
}
}  // namespace

Status writeSavedMapOf(storage::Store& store, const std::string& name, const MapCopy& copy,
                       std::optional<MapCopy>* base) {
  Status written = absl::FailedPreconditionError("no base");
  if (base->has_value()) {
    written = store.updateSavedMap(name, copy.frames, *copy.map, *copy.labels, *(*base)->map,
                                   *(*base)->labels);
  }
  if (absl::IsFailedPrecondition(written)) {
    written = store.putSavedMap(name, copy.frames, *copy.map, *copy.labels);
  }
  if (written.ok()) {
    *base = copy;
  } else {
    base->reset();
  }
  return written;
}

void PublishedScenes::recordPublished(double ms) {
  std::lock_guard lock(mutex_);
  ++counters_.published;
  counters_.publish_ms += ms;
}

std::shared_ptr<const tsdf::TsdfLayer> PublishedScenes::scene(const std::string& name) {
  // An ended session's scene first: between storing its final map and ending, a session has
  // both, and the saved one is the older.
  auto stored = store_->scene(name);
  if (!stored.ok()) {
    logger("server")->warn("reading the scene of session {}: {}", name,
                           std::string(stored.status().message()));
    return nullptr;
  }
  if (*stored != nullptr) return *std::move(stored);
  auto frames = store_->savedMapFrames(name);
  if (!frames.ok()) {
    logger("server")->warn("reading the published map of session {}: {}", name,
                           std::string(frames.status().message()));
    return nullptr;
  }
  std::lock_guard lock(mutex_);
  if (*frames < 0) {
    // Nothing published, or the session ended meanwhile: the database reads its stored scene
    // when this answers null.
    cache_.erase(name);
    return nullptr;
  }
  if (auto it = cache_.find(name); it != cache_.end() && it->second.first == *frames) {
    return it->second.second;
  }
  const auto start = std::chrono::steady_clock::now();
  auto saved = store_->savedMap(name);
  if (!saved.ok() || saved->map == nullptr) {
    // Ended (and its saved map deleted) between the two reads: its scene is stored now, and the
    // database reads it when this answers null.
    return nullptr;
  }
  if (cache_.size() >= kMaxCached) cache_.clear();
  cache_[name] = {saved->frames, saved->map};
  ++counters_.read;
  counters_.read_ms += msSince(start);
  logger("server")->debug("session {}: published map of {} frames read ({:.0f} ms)", name,
                          saved->frames, msSince(start));
  return saved->map;
}

PublishedScenes::Counters PublishedScenes::counters() const {
  std::lock_guard lock(mutex_);
  return counters_;
}

}  // namespace objdb::server
