// Live maps across servers. Model-to-scene verification needs the map of every session a model
// was seen in. One server verifies poses in its own live sessions against each session's newest
// extraction snapshot (LiveSession::scene). When several servers share one database, a session
// live on another server has no map this server can read, unless that server publishes it: while
// another server holds a session lease, each extraction's snapshot is stored as the session's
// saved map before the segments extracted with it are inserted (writeSavedMapOf, by the service),
// and the other servers read it back (scene), decoded once per version. So a model's observation in a live session is never newer than the map published for
// that session, and every server verifies against the snapshot the owner itself would use, as of
// the owner's latest extraction.
#pragma once

#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <utility>

#include "absl/container/flat_hash_map.h"
#include "core/common/status.h"
#include "core/tsdf/tsdf_layer.h"
#include "server/session/live_session.h"
#include "storage/store.h"

namespace objdb::server {

// Writes `copy` as session `name`'s saved map: the blocks that differ from `base` (the copy last
// written, null when none was) when there is one, else (or when the store holds no saved map to
// update) the whole map. On success `base` becomes `copy`; on failure it is reset, so that the
// next write is whole.
Status writeSavedMapOf(storage::Store& store, const std::string& name, const MapCopy& copy,
                       std::optional<MapCopy>* base);

class PublishedScenes {
 public:
  explicit PublishedScenes(storage::Store* store) : store_(store) {}

  // A map this server published (written as its session's saved map while other servers
  // were at work on the database), in `ms`.
  void recordPublished(double ms);

  // The map to verify poses in session `name` against when this server does not stream it: its
  // stored scene when it has ended, else the map its server published last (decoded on first
  // use of each version); null when there is neither (or the store cannot say: logged).
  std::shared_ptr<const tsdf::TsdfLayer> scene(const std::string& name);

  struct Counters {
    uint64_t published = 0;      // maps this server published (recordPublished)
    double publish_ms = 0.0;     // time spent encoding and writing them
    uint64_t read = 0;           // other servers' maps decoded here
    double read_ms = 0.0;        // time spent reading and decoding them
  };
  Counters counters() const;

 private:
  // Decoded maps kept; beyond this many sessions the cache starts over (each is read again
  // when next needed).
  static constexpr size_t kMaxCached = 32;

  storage::Store* const store_;
  mutable std::mutex mutex_;  // guards what follows
  // Session name -> (saved map's frame count, its decoded TSDF).
  absl::flat_hash_map<std::string, std::pair<int64_t, std::shared_ptr<const tsdf::TsdfLayer>>>
      cache_;
  Counters counters_;
};

}  // namespace objdb::server
