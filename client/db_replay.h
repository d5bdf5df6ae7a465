// `objdb db replay`: the database's raw segments inserted again, in the order their rows were
// created, through one object database in memory, and the result compared with what the store
// holds. Several servers on one database insert under one writer lock; the rows of first
// insertions are created under that lock, so their order is the order the servers took it. When
// every segment was inserted once (no re-extraction or withdrawal: e.g. sessions extracted only
// at their end), the store must hold exactly what one server running the inserts in that order
// holds: the same models (as sets of segments) and the same number of merges. That is what "the
// same result" means for concurrent sessions, and this checks it.
#pragma once

#include <string>
#include <vector>

#include "core/common/params.h"
#include "core/common/status.h"
#include "storage/store.h"

namespace objdb::cli {

struct ReplayReport {
  size_t segments = 0;            // raw segments replayed
  size_t models_stored = 0;       // active models in the store
  size_t models_replayed = 0;     // models of the replay
  size_t merges_stored = 0;
  size_t merges_replayed = 0;
  // Models (their segments, "session/label" joined by ", ") held by one side only.
  std::vector<std::string> only_stored, only_replayed;
  bool same() const {
    return only_stored.empty() && only_replayed.empty() && merges_stored == merges_replayed;
  }
};

// Replays `store` with `params` (the database sections are what the servers ran with).
StatusOr<ReplayReport> replayInCreationOrder(const storage::Store& store, const Params& params);

}  // namespace objdb::cli
