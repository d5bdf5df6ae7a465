#include "core/database/global_index.h"

#include <algorithm>
#include <cstring>

#include <Eigen/Core>

namespace objdb::database {

void GlobalIndex::put(int64_t id, const std::vector<float>& descriptor) {
  const bool empty =
      std::all_of(descriptor.begin(), descriptor.end(), [](float v) { return v == 0.0f; });
  if (empty || (dims_ != 0 && int(descriptor.size()) != dims_)) {
    erase(id);
    return;
  }
  if (dims_ == 0) dims_ = int(descriptor.size());
  const auto it = row_.find(id);
  size_t row = 0;
  if (it != row_.end()) {
    row = it->second;
  } else {
    row = ids_.size();
    ids_.push_back(id);
    rows_.resize(rows_.size() + size_t(dims_));
    row_[id] = row;
  }
  std::memcpy(rows_.data() + row * size_t(dims_), descriptor.data(), sizeof(float) * size_t(dims_));
}

void GlobalIndex::erase(int64_t id) {
  const auto it = row_.find(id);
  if (it == row_.end()) return;
  // The last row moves into the gap: one row copied, whatever the size.
  const size_t row = it->second, last = ids_.size() - 1;
  row_.erase(it);
  if (row != last) {
    std::memcpy(rows_.data() + row * size_t(dims_), rows_.data() + last * size_t(dims_),
                sizeof(float) * size_t(dims_));
    ids_[row] = ids_[last];
    row_[ids_[row]] = row;
  }
  ids_.pop_back();
  rows_.resize(ids_.size() * size_t(dims_));
}

std::vector<int64_t> GlobalIndex::ids() const {
  std::vector<int64_t> out = ids_;
  std::sort(out.begin(), out.end());
  return out;
}

std::vector<GlobalIndex::Hit> GlobalIndex::nearest(const std::vector<float>& query, int n,
                                                   int64_t exclude) const {
  if (ids_.empty() || int(query.size()) != dims_) return {};
  using Matrix = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  const Eigen::Map<const Matrix> rows(rows_.data(), Eigen::Index(ids_.size()), dims_);
  const Eigen::Map<const Eigen::VectorXf> q(query.data(), dims_);
  const Eigen::VectorXf similarity = rows * q;
  std::vector<Hit> hits;
  hits.reserve(ids_.size());
  for (size_t i = 0; i < ids_.size(); ++i) {
    if (ids_[i] != exclude) hits.push_back({ids_[i], similarity[Eigen::Index(i)]});
  }
  const auto order = [](const Hit& a, const Hit& b) {
    return a.similarity != b.similarity ? a.similarity > b.similarity : a.id < b.id;
  };
  const size_t keep = n <= 0 ? hits.size() : std::min(hits.size(), size_t(n));
  std::partial_sort(hits.begin(), hits.begin() + std::ptrdiff_t(keep), hits.end(), order);
  hits.resize(keep);
  return hits;
}

}  // namespace objdb::database
