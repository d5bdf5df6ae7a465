// The prefilter's descriptor index over every matchable model, kept up to date one model at a
// time: no rebuild of the whole index per insert. A logarithmic method (Bentley and Saxe): the
// descriptors live in a few static kd-trees (matching::DescriptorIndex) of geometrically growing
// size; a model put in gets a tree of its own, and the two newest trees are rebuilt into one while
// the older holds at most twice the newer's descriptors, so each descriptor is rebuilt O(log n)
// times over its life. A model taken out is a tombstone in its tree until the dead reach half of
// that tree, which is then rebuilt from its live descriptors. Queries ask every tree and merge:
// the k nearest live descriptors overall, exactly what one tree over them all returns. With an
// epsilon > 0 each tree's search is approximate (matching::DescriptorIndex): the cost of a query
// then grows far slower than the number of descriptors, and nearestExhaustive measures what it
// misses.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <tuple>
#include <utility>
#include <vector>

#include "core/matching/registration.h"
#include "core/model/object_model.h"

namespace objdb::database {

class PrefilterIndex {
 public:
  struct Neighbour {
    int64_t owner = 0;      // the model the descriptor belongs to
    float similarity = 0.0f;
  };

  explicit PrefilterIndex(float epsilon = 0.0f) : epsilon_(epsilon) {}

  // Models (id, descriptors) into an empty index (a database opened on its store): in `threads`
  // trees of about equal size, built in parallel (one tree over 5 million descriptors takes half
  // a minute to build). Takes the descriptors: each model's list is left empty once it is in its
  // tree, so that opening holds each descriptor about once (132 bytes; 100,000 chair models hold
  // 50 million).
  void load(const std::vector<std::pair<int64_t, std::vector<model::Fpfh>*>>& models,
            int threads = 1);
  // Adds model `id`'s descriptors, replacing those it had.
  void put(int64_t id, const std::vector<model::Fpfh>& descriptors);
  // Takes model `id`'s descriptors out (nothing when it has none here): they stay as tombstones
  // until half their tree is dead, which is then rebuilt (or dropped when nothing is left).
  void erase(int64_t id);
  // The k nearest live descriptors to `query` (Euclidean, as the kd-trees search), nearest first
  // (ties: lower owner, then the older descriptor), with their similarity to it.
  std::vector<Neighbour> nearest(const model::Fpfh& query, int k) const;
  // The same by a scan of every live descriptor: the exact answer whatever epsilon is, in time
  // linear in size() (for measuring the approximate search's recall).
  std::vector<Neighbour> nearestExhaustive(const model::Fpfh& query, int k) const;

  // Model `id`'s descriptors as put (empty when it has none here).
  std::vector<model::Fpfh> descriptorsOf(int64_t id) const;

  size_t size() const { return live_; }  // live descriptors
  size_t trees() const { return trees_.size(); }
  // Descriptors put into a kd-tree build so far (the work the index did; a full rebuild per
  // insert would be the live count each time).
  size_t rebuilt() const { return rebuilt_; }

 private:
  struct Tree {
    std::vector<int64_t> owner;       // per descriptor
    std::vector<uint64_t> sequence;   // per descriptor: when it was put (global order)
    std::unique_ptr<matching::DescriptorIndex> index;  // holds the descriptors (the only copy)
    size_t dead = 0;
    const std::vector<model::Fpfh>& descriptors() const { return index->descriptors(); }
    size_t size() const { return owner.size(); }
    size_t live() const { return size() - dead; }
  };
  // (distance², owner, sequence, similarity): the order of the answer, nearest first.
  using Candidate = std::tuple<float, int64_t, uint64_t, float>;
  static std::vector<Neighbour> nearestOf(std::vector<Candidate> found, int k);
  // Rebuilds `trees` into one tree of their live descriptors (null when none is left).
  std::unique_ptr<Tree> rebuild(std::vector<std::unique_ptr<Tree>> trees);
  bool alive(const Tree& tree, size_t i) const;

  std::vector<std::unique_ptr<Tree>> trees_;  // oldest (largest) first
  struct Place {
    Tree* tree = nullptr;
    uint64_t first = 0;  // sequence of its first descriptor
    size_t count = 0;
  };
  std::map<int64_t, Place> where_;  // live model → where its descriptors are
  float epsilon_ = 0.0f;
  uint64_t next_sequence_ = 0;
  size_t live_ = 0;
  size_t rebuilt_ = 0;
};

}  // namespace objdb::database
