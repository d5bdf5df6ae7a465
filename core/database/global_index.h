// The first stage of retrieval (issue 48): every matchable model's global descriptor
// (model/global_descriptor.h) in one row-major matrix, searched exactly by one matrix-vector
// product (Eigen) for the models most similar to a query. At 100,000 models of 1,056 floats the
// search reads 422 MB once, tens of milliseconds on one core (bench/insert_bench prints it), and
// needs no build step: opening a store fills the rows, a merge or removal changes one row. An
// approximate index (FAISS, hnswlib) would only pay beyond that, and would have to be persisted
// and kept in step; the exact scan needs neither.
#pragma once

#include <cstddef>
#include <cstdint>
#include <unordered_map>
#include <utility>
#include <vector>

namespace objdb::database {

class GlobalIndex {
 public:
  struct Hit {
    int64_t id = 0;
    float similarity = 0.0f;  // cosine of the two global descriptors
  };

  // Adds model `id`'s descriptor, replacing the one it had. An empty or all-zero descriptor takes
  // the model out (it has nothing to compare). Every descriptor must have the first one's length;
  // a descriptor of another length takes the model out too (a store of another codebook).
  void put(int64_t id, const std::vector<float>& descriptor);
  void erase(int64_t id);
  // The `n` models most similar to `query` (n ≤ 0: every model), most similar first; ties by the
  // lower id. `exclude` is left out (the query's own model). Empty for a query of another length.
  std::vector<Hit> nearest(const std::vector<float>& query, int n, int64_t exclude = 0) const;

  // Every model held, ascending.
  std::vector<int64_t> ids() const;

  size_t size() const { return ids_.size(); }
  int dimensions() const { return dims_; }
  bool contains(int64_t id) const { return row_.count(id) > 0; }

 private:
  int dims_ = 0;
  std::vector<float> rows_;  // size() × dims_
  std::vector<int64_t> ids_;
  std::unordered_map<int64_t, size_t> row_;
};

}  // namespace objdb::database
