// The approximate prefilter's recall against the exhaustive vote, over the inserts of a run
// (ObjectDatabase::measurePrefilterRecall): of the candidates the exact vote over every stored
// descriptor picks, the share the prefilter also picked; inserts that kept all of them; inserts
// whose first candidate is the same.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

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

// The short list's recall (DatabaseParams::shortlist) against the merges a run accepted: for
// every accepted candidate (the segment's merge and each co-accepted model), its rank among the
// stored models by global similarity (InsertReport::global_ranking). Run with shortlist 0 for
// today's full vote to be the reference; with a list, its own accepted merges are counted.
struct ShortlistRecall {
  std::vector<size_t> ranks;  // 0-based; SIZE_MAX: not ranked (no global descriptor)
  size_t models = 0;          // the most models ranked in one insert

  void add(const database::InsertReport& r) {
    if (r.global_ranking.empty()) return;
    models = std::max(models, r.global_ranking.size());
    auto count = [&](const database::CandidateResult& c) {
      if (!c.accepted) return;
      const auto it = std::find(r.global_ranking.begin(), r.global_ranking.end(), c.model_id);
      ranks.push_back(it == r.global_ranking.end() ? SIZE_MAX
                                                   : size_t(it - r.global_ranking.begin()));
    };
    for (const auto& c : r.results) count(c);
    for (const auto& c : r.co_accepted) count(c);
  }

  double recallAt(size_t length) const {
    if (ranks.empty()) return 1.0;
    size_t in = 0;
    for (size_t rank : ranks) in += rank < length ? 1 : 0;
    return double(in) / double(ranks.size());
  }

  std::string summary() const {
    std::string out = absl::StrFormat(
        "short list against %d accepted merges (up to %d models ranked): recall", ranks.size(),
        models);
    for (size_t length : {1, 4, 16, 64, 256, 1024}) {
      out += absl::StrFormat(" @%d %.1f %%", length, 100.0 * recallAt(length));
    }
    size_t worst = 0;
    for (size_t rank : ranks) worst = std::max(worst, rank == SIZE_MAX ? rank : rank + 1);
    out += worst == SIZE_MAX ? "; one not ranked" : absl::StrFormat("; worst rank %d", worst);
    return out;
  }
};

}  // namespace objdb
