// The approximate prefilter's recall against the exhaustive vote, over the inserts of a run
// (ObjectDatabase::measurePrefilterRecall): of the candidates the exact vote over every stored
// descriptor picks, the share the prefilter also picked; inserts that kept all of them; inserts
// whose first candidate is the same.
#pragma once

#include <algorithm>
#include <cstddef>
#include <string>

#include "absl/strings/str_format.h"
#include "core/database/object_database.h"

namespace objdb {

struct PrefilterRecall {
  size_t exhaustive = 0, kept = 0, inserts = 0, complete = 0, same_first = 0;

  void add(const database::InsertReport& r) {
    if (r.exhaustive_candidates.empty()) return;
    ++inserts;
    size_t hit = 0;
    for (int64_t id : r.exhaustive_candidates) {
      hit += std::count(r.prefilter_candidates.begin(), r.prefilter_candidates.end(), id) > 0;
    }
    exhaustive += r.exhaustive_candidates.size();
    kept += hit;
    complete += hit == r.exhaustive_candidates.size() ? 1 : 0;
    same_first += !r.prefilter_candidates.empty() &&
                  r.prefilter_candidates.front() == r.exhaustive_candidates.front();
  }

  std::string summary() const {
    return absl::StrFormat(
        "prefilter against the exhaustive vote: %.1f %% of its candidates kept (%d of %d); %d of "
        "%d inserts kept all, %d the same first",
        exhaustive ? 100.0 * double(kept) / double(exhaustive) : 100.0, kept, exhaustive,
        complete, inserts, same_first);
  }
};

}  // namespace objdb
