// ObjectDatabase's retrieval (issue 48): which stored models a new one is registered against.
// The first stage ranks every matchable model by its global descriptor (GlobalIndex, in memory,
// read from the store when the database opens); the second is the descriptor vote, over the
// local descriptors of the DatabaseParams::shortlist first models only, read from the store per
// insert (a cache keeps the recent ones). With shortlist 0 the vote runs over every model's
// descriptors, held in memory in the PrefilterIndex, as before the short list existed.
#include <algorithm>
#include <map>
#include <set>

#include "core/common/logging.h"
#include "core/database/object_database.h"
#include "core/database/parallel_for.h"
#include "core/model/global_descriptor.h"

namespace objdb::database {
namespace {

// Models whose global descriptor is computed and written back per step when opening a store
// that lacks them (an older schema, another codebook version): the progress step.
constexpr size_t kGlobalBatch = 512;

}  // namespace

Status ObjectDatabase::loadGlobalIndex(const std::vector<MatchEntry*>& matchable) {
  std::vector<MatchEntry*> missing;
  for (MatchEntry* e : matchable) {
    if (e->global.empty()) {
      missing.push_back(e);
    } else {
      global_.put(e->id, e->global);
      std::vector<float>().swap(e->global);  // the index holds its copy
    }
  }
  if (missing.empty()) return Status();
  // Computed from the local descriptors (in the entries, or read from the store), and kept in the
  // store so that the next opening reads them.
  auto log = logger("database");
  log->info("object database: {} of {} stored models have no global descriptor of codebook "
            "version {}: computing them from their local descriptors",
            missing.size(), matchable.size(), model::kCodebookVersion);
  const size_t threads = size_t(std::max(1, params_.database.threads));
  size_t store_failures = 0;
  for (size_t begin = 0; begin < missing.size(); begin += kGlobalBatch) {
    const size_t end = std::min(missing.size(), begin + kGlobalBatch);
    std::vector<std::vector<model::Fpfh>> read;
    if (params_.database.shortlist > 0) {
      std::vector<int64_t> ids;
      for (size_t i = begin; i < end; ++i) ids.push_back(missing[i]->id);
      OBJDB_ASSIGN_OR_RETURN(read, store_->descriptorsOf(ids));
    }
    std::vector<std::pair<int64_t, std::vector<float>>> computed(end - begin);
    parallelFor(begin, end, threads, [&](size_t i) {
      const std::vector<model::Fpfh>& local =
          read.empty() ? missing[i]->descriptors : read[i - begin];
      // Read without its descriptors, an entry was taken to have one per keypoint: one without
      // is not matchable after all (no global descriptor, not in the index).
      if (local.size() != missing[i]->num_keypoints) return;
      computed[i - begin] = {missing[i]->id, model::globalDescriptor(local)};
    });
    std::erase_if(computed, [](const auto& c) { return c.second.empty(); });
    for (const auto& [id, global] : computed) global_.put(id, global);
    if (Status kept = store_->putGlobalDescriptors(computed); !kept.ok()) {
      ++store_failures;  // a read-only store: computed again at the next opening
      if (store_failures == 1) {
        log->warn("object database: global descriptors not kept in the store: {}",
                  std::string(kept.message()));
      }
    }
    log->info("object database: global descriptors computed for {} of {} models", end,
              missing.size());
  }
  return Status();
}

void ObjectDatabase::forgetDescriptors(int64_t id) {
  const auto it = descriptor_cache_.find(id);
  if (it == descriptor_cache_.end()) return;
  cached_descriptors_ -= it->second.descriptors->size();
  descriptor_lru_.erase(it->second.lru);
  descriptor_cache_.erase(it);
}

StatusOr<std::vector<std::shared_ptr<const std::vector<model::Fpfh>>>>
ObjectDatabase::cachedDescriptors(const std::vector<int64_t>& ids) {
  std::vector<std::shared_ptr<const std::vector<model::Fpfh>>> out(ids.size());
  std::vector<int64_t> missing;
  std::vector<size_t> slots;
  for (size_t i = 0; i < ids.size(); ++i) {
    const auto it = descriptor_cache_.find(ids[i]);
    if (it == descriptor_cache_.end()) {
      missing.push_back(ids[i]);
      slots.push_back(i);
      continue;
    }
    descriptor_lru_.splice(descriptor_lru_.begin(), descriptor_lru_, it->second.lru);
    out[i] = it->second.descriptors;
  }
  if (missing.empty()) return out;
  OBJDB_ASSIGN_OR_RETURN(std::vector<std::vector<model::Fpfh>> read,
                         store_->descriptorsOf(missing));
  for (size_t j = 0; j < missing.size(); ++j) {
    auto descriptors = std::make_shared<const std::vector<model::Fpfh>>(std::move(read[j]));
    out[slots[j]] = descriptors;
    descriptor_lru_.push_front(missing[j]);
    descriptor_cache_[missing[j]] = {descriptors, descriptor_lru_.begin()};
    cached_descriptors_ += descriptors->size();
  }
  // The least recently used go while the cache holds more than its budget (not the ones just
  // read: they are at the front).
  while (cached_descriptors_ > kCachedDescriptors && descriptor_lru_.size() > missing.size()) {
    forgetDescriptors(descriptor_lru_.back());
  }
  return out;
}

std::vector<int64_t> ObjectDatabase::shortlistFor(const std::vector<float>& global,
                                                  int64_t exclude) const {
  std::vector<int64_t> ids;
  for (const GlobalIndex::Hit& hit : global_.nearest(global, params_.database.shortlist, exclude)) {
    ids.push_back(hit.id);
  }
  return ids;
}

StatusOr<std::vector<int64_t>> ObjectDatabase::candidatesFor(const model::ObjectModel& model,
                                                             bool exhaustive,
                                                             std::vector<int64_t>* shortlist) {
  // The segment's global descriptor before the lock: matches and inserts wait for each other
  // only where they share the caches.
  const std::vector<float> global = params_.database.shortlist > 0 && !exhaustive
                                        ? model::globalDescriptor(model.descriptors)
                                        : std::vector<float>();
  std::lock_guard lock(mutex_);
  const int k = params_.database.prefilter_neighbours;
  // The models voted over: every one (shortlist 0: the prefilter holds their descriptors), or
  // the short list (the whole of it when exhaustive), their descriptors from the cache or store.
  const PrefilterIndex* voters = &prefilter_;
  PrefilterIndex listed(params_.database.prefilter_epsilon);
  if (params_.database.shortlist > 0) {
    std::vector<int64_t> ids;
    if (exhaustive) {
      for (const int64_t id : global_.ids()) {
        if (id != model.id) ids.push_back(id);
      }
    } else {
      ids = shortlistFor(global, model.id);
      if (shortlist != nullptr) *shortlist = ids;
    }
    OBJDB_ASSIGN_OR_RETURN(const auto descriptors, cachedDescriptors(ids));
    std::vector<std::vector<model::Fpfh>> copies(ids.size());
    std::vector<std::pair<int64_t, std::vector<model::Fpfh>*>> models;
    for (size_t i = 0; i < ids.size(); ++i) {
      copies[i] = *descriptors[i];
      models.emplace_back(ids[i], &copies[i]);
    }
    listed.load(models, params_.database.threads);
    voters = &listed;
  }
  // The searches on database.threads threads (the index is only read), the votes in descriptor
  // order: the same candidates on any number of threads.
  const size_t n = model.descriptors.size();
  std::vector<std::vector<PrefilterIndex::Neighbour>> found(n);
  parallelFor(0, n, size_t(std::max(1, params_.database.threads)), [&](size_t i) {
    const model::Fpfh& d = model.descriptors[i];
    found[i] = exhaustive ? voters->nearestExhaustive(d, k) : voters->nearest(d, k);
  });
  std::map<int64_t, int> votes;
  std::set<int64_t> voted;
  for (const auto& neighbours : found) {
    voted.clear();
    for (const auto& [owner, similarity] : neighbours) {
      if (similarity < params_.matching.similarity_threshold) continue;
      if (owner != model.id && voted.insert(owner).second) ++votes[owner];
    }
  }
  std::vector<std::pair<int, int64_t>> ranked;
  for (const auto& [id, n] : votes) {
    if (n >= params_.database.prefilter_min_votes) ranked.emplace_back(-n, id);
  }
  std::sort(ranked.begin(), ranked.end());
  std::vector<int64_t> ids;
  for (const auto& [negative_votes, id] : ranked) {
    if (ids.size() >= size_t(params_.database.max_candidates)) break;
    ids.push_back(id);
  }
  return ids;
}

}  // namespace objdb::database
