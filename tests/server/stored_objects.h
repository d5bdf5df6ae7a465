// What the server crash and resume tests check of the store: which reported objects it no longer
// holds, and its active models as text to compare two databases by.
#pragma once

#include <algorithm>
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "storage/store.h"

namespace objdb::testing {

// The objects of `objects` (ids a server reported) that `store` does not hold. An object is held
// when it is active, or when it joined another object later (state merged) whose merged_into
// chain ends at an active one.
inline std::vector<uint64_t> objectsNotHeld(const storage::Store& store,
                                            const std::vector<uint64_t>& objects) {
  storage::ModelQuery all;
  all.limit = 1000000;
  all.include_merged = true;
  const std::vector<storage::ModelSummary> summaries = store.modelSummaries(all).value();
  std::map<int64_t, int64_t> merged_into;
  std::vector<int64_t> active;
  for (const auto& m : summaries) {
    if (m.state == "merged") merged_into[m.id] = m.merged_into;
    if (m.state == "active") active.push_back(m.id);
  }
  std::vector<uint64_t> lost;
  for (const uint64_t id : objects) {
    int64_t holder = int64_t(id);
    for (int hop = 0; hop < 100 && merged_into.count(holder); ++hop) holder = merged_into[holder];
    if (std::find(active.begin(), active.end(), holder) == active.end()) lost.push_back(id);
  }
  return lost;
}

// Each active model of `store` as "points N merges M poses S/L …" (its poses' sessions and
// labels), sorted: two databases built from the same frames hold the same lines, whatever ids
// their models got.
inline std::vector<std::string> activeModels(const storage::Store& store) {
  storage::ModelQuery all;
  all.limit = 1000000;
  const std::vector<storage::ModelSummary> summaries = store.modelSummaries(all).value();
  std::vector<std::string> lines;
  for (const auto& m : summaries) {
    std::string line = "points " + std::to_string(m.num_points) + " merges " +
                       std::to_string(m.merges) + " poses";
    for (const auto& pose : m.observations) {
      line += " " + pose.session + "/" + std::to_string(pose.label);
    }
    lines.push_back(line);
  }
  std::sort(lines.begin(), lines.end());
  return lines;
}

}  // namespace objdb::testing
