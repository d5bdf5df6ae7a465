#include "core/database/prefilter_index.h"

#include <algorithm>
#include <thread>
#include <tuple>

#include "core/model/global_descriptor.h"

namespace objdb::database {

using model::fpfhSquaredDistance;

std::vector<PrefilterIndex::Neighbour> PrefilterIndex::nearestOf(std::vector<Candidate> found,
                                                                 int k) {
  std::sort(found.begin(), found.end());
  if (found.size() > size_t(k)) found.resize(size_t(k));
  std::vector<Neighbour> out;
  out.reserve(found.size());
  for (const auto& [d2, owner, sequence, similarity] : found) out.push_back({owner, similarity});
  return out;
}

bool PrefilterIndex::alive(const Tree& tree, size_t i) const {
  const auto it = where_.find(tree.owner[i]);
  return it != where_.end() && it->second.tree == &tree && tree.sequence[i] >= it->second.first;
}

std::unique_ptr<PrefilterIndex::Tree> PrefilterIndex::rebuild(
    std::vector<std::unique_ptr<Tree>> trees) {
  auto out = std::make_unique<Tree>();
  size_t live = 0;
  for (const auto& t : trees) live += t->live();
  std::vector<model::Fpfh> descriptors;
  descriptors.reserve(live);
  out->owner.reserve(live);
  out->sequence.reserve(live);
  for (const auto& t : trees) {
    for (size_t i = 0; i < t->size(); ++i) {
      if (!alive(*t, i)) continue;
      descriptors.push_back(t->descriptors()[i]);
      out->owner.push_back(t->owner[i]);
      out->sequence.push_back(t->sequence[i]);
    }
  }
  // A model's descriptors are contiguous in every tree (put together, kept in order).
  for (size_t i = 0; i < out->owner.size(); ++i) {
    if (i == 0 || out->owner[i] != out->owner[i - 1]) where_[out->owner[i]].tree = out.get();
  }
  if (descriptors.empty()) return nullptr;
  rebuilt_ += descriptors.size();
  out->index = std::make_unique<matching::DescriptorIndex>(std::move(descriptors), epsilon_);
  return out;
}

void PrefilterIndex::erase(int64_t id) {
  const auto it = where_.find(id);
  if (it == where_.end()) return;
  Tree* tree = it->second.tree;
  tree->dead += it->second.count;
  live_ -= it->second.count;
  where_.erase(it);
  if (2 * tree->dead < tree->size()) return;
  const auto slot = std::find_if(trees_.begin(), trees_.end(),
                                 [&](const std::unique_ptr<Tree>& t) { return t.get() == tree; });
  std::vector<std::unique_ptr<Tree>> one;
  one.push_back(std::move(*slot));
  std::unique_ptr<Tree> rebuilt = rebuild(std::move(one));
  if (rebuilt) {
    *slot = std::move(rebuilt);
  } else {
    trees_.erase(slot);
  }
}

void PrefilterIndex::load(
    const std::vector<std::pair<int64_t, std::vector<model::Fpfh>*>>& models, int threads) {
  size_t total = 0;
  for (const auto& [id, descriptors] : models) total += descriptors->size();
  // `threads` trees of about equal size (a model's descriptors stay in one), built in parallel:
  // first which tree each model goes to, so that each tree's list is allocated once.
  const size_t parts = size_t(std::max(1, threads));
  const size_t per_tree = std::max<size_t>(1, (total + parts - 1) / parts);
  std::vector<size_t> tree_of(models.size());
  std::vector<size_t> sizes(1, 0);
  for (size_t m = 0; m < models.size(); ++m) {
    const size_t n = models[m].second->size();
    if (n == 0) continue;
    if (sizes.back() >= per_tree && sizes.size() < parts) sizes.push_back(0);
    tree_of[m] = sizes.size() - 1;
    sizes.back() += n;
  }
  std::vector<std::unique_ptr<Tree>> loaded;
  std::vector<std::vector<model::Fpfh>> lists(sizes.size());
  for (size_t t = 0; t < sizes.size(); ++t) {
    loaded.push_back(std::make_unique<Tree>());
    lists[t].reserve(sizes[t]);
    loaded[t]->owner.reserve(sizes[t]);
    loaded[t]->sequence.reserve(sizes[t]);
  }
  for (size_t m = 0; m < models.size(); ++m) {
    const auto& [id, descriptors] = models[m];
    erase(id);
    if (descriptors->empty()) continue;
    Tree* tree = loaded[tree_of[m]].get();
    std::vector<model::Fpfh>& list = lists[tree_of[m]];
    where_[id] = Place{tree, next_sequence_, descriptors->size()};
    list.insert(list.end(), descriptors->begin(), descriptors->end());
    tree->owner.insert(tree->owner.end(), descriptors->size(), id);
    for (size_t i = 0; i < descriptors->size(); ++i) tree->sequence.push_back(next_sequence_++);
    live_ += descriptors->size();
    std::vector<model::Fpfh>().swap(*descriptors);  // taken: its memory goes now
  }
  std::vector<std::thread> builders;
  for (size_t t = 0; t < loaded.size(); ++t) {
    if (lists[t].empty()) continue;
    rebuilt_ += lists[t].size();
    builders.emplace_back([this, tree = loaded[t].get(), list = &lists[t]] {
      tree->index = std::make_unique<matching::DescriptorIndex>(std::move(*list), epsilon_);
    });
  }
  for (auto& builder : builders) builder.join();
  for (auto& tree : loaded) {
    if (tree->index != nullptr) trees_.push_back(std::move(tree));
  }
}

void PrefilterIndex::put(int64_t id, const std::vector<model::Fpfh>& descriptors) {
  erase(id);
  if (descriptors.empty()) return;
  auto tree = std::make_unique<Tree>();
  tree->owner.assign(descriptors.size(), id);
  const uint64_t first = next_sequence_;
  for (size_t i = 0; i < descriptors.size(); ++i) tree->sequence.push_back(next_sequence_++);
  tree->index = std::make_unique<matching::DescriptorIndex>(descriptors, epsilon_);
  rebuilt_ += descriptors.size();
  where_[id] = Place{tree.get(), first, descriptors.size()};
  live_ += descriptors.size();
  trees_.push_back(std::move(tree));
  // Binary-counter merging: the newest two become one while the older is at most twice the newer.
  while (trees_.size() >= 2 &&
         trees_[trees_.size() - 2]->live() <= 2 * trees_.back()->live()) {
    std::vector<std::unique_ptr<Tree>> two;
    two.push_back(std::move(trees_[trees_.size() - 2]));
    two.push_back(std::move(trees_.back()));
    trees_.resize(trees_.size() - 2);
    std::unique_ptr<Tree> merged = rebuild(std::move(two));
    if (merged) trees_.push_back(std::move(merged));
  }
}

std::vector<model::Fpfh> PrefilterIndex::descriptorsOf(int64_t id) const {
  const auto it = where_.find(id);
  if (it == where_.end()) return {};
  const Tree& tree = *it->second.tree;
  // Contiguous in its tree, from the first whose sequence is the model's first.
  const auto first = std::lower_bound(tree.sequence.begin(), tree.sequence.end(), it->second.first);
  const size_t begin = size_t(first - tree.sequence.begin());
  return {tree.descriptors().begin() + std::ptrdiff_t(begin),
          tree.descriptors().begin() + std::ptrdiff_t(begin + it->second.count)};
}

std::vector<PrefilterIndex::Neighbour> PrefilterIndex::nearest(const model::Fpfh& query,
                                                               int k) const {
  // The trees' k nearest are by Euclidean distance, so the merge is too: (distance², owner,
  // sequence, similarity).
  std::vector<Candidate> found;
  if (k <= 0) return {};
  for (const auto& tree : trees_) {
    // The k nearest live ones of this tree: ask for k (more when it has dead ones), and again for
    // four times as many while dead ones among them leave fewer than k and the tree has more.
    const size_t n = tree->size();
    size_t want = std::min(n, size_t(k) + std::min(tree->dead, size_t(k)));
    std::vector<std::pair<uint32_t, float>> hits;
    while (true) {
      hits = tree->index->nearest(query, int(want));
      size_t live = 0;
      for (const auto& hit : hits) live += alive(*tree, hit.first) ? 1 : 0;
      if (live >= size_t(k) || want >= n) break;
      want = std::min(n, 4 * want);
    }
    size_t taken = 0;
    for (const auto& [i, similarity] : hits) {
      if (!alive(*tree, i) || taken == size_t(k)) continue;
      ++taken;
      found.emplace_back(fpfhSquaredDistance(query, tree->descriptors()[i]), tree->owner[i],
                         tree->sequence[i], similarity);
    }
  }
  return nearestOf(std::move(found), k);
}

std::vector<PrefilterIndex::Neighbour> PrefilterIndex::nearestExhaustive(
    const model::Fpfh& query, int k) const {
  if (k <= 0) return {};
  struct Scanned {
    Candidate key;
    const model::Fpfh* descriptor;
    bool operator<(const Scanned& o) const { return key < o.key; }
  };
  std::vector<Scanned> scanned;
  scanned.reserve(live_);
  for (const auto& tree : trees_) {
    for (size_t i = 0; i < tree->size(); ++i) {
      if (!alive(*tree, i)) continue;
      scanned.push_back({{fpfhSquaredDistance(query, tree->descriptors()[i]), tree->owner[i],
                          tree->sequence[i], 0.0f},
                         &tree->descriptors()[i]});
    }
  }
  const size_t keep = std::min(scanned.size(), size_t(k));
  std::partial_sort(scanned.begin(), scanned.begin() + std::ptrdiff_t(keep), scanned.end());
  std::vector<Candidate> found;
  found.reserve(keep);
  for (size_t i = 0; i < keep; ++i) {
    found.push_back(scanned[i].key);
    std::get<3>(found.back()) = matching::fpfhSimilarity(query, *scanned[i].descriptor);
  }
  return nearestOf(std::move(found), k);
}

}  // namespace objdb::database
