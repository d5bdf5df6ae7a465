// fn(i) for every i in [begin, end), on up to `threads` threads, the caller one of them; each i
// is taken by the next free thread. For the database's per-insert loops (candidate searches,
// global descriptors), which start a few threads a few times per insert.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <functional>
#include <thread>
#include <vector>

namespace objdb::database {

inline void parallelFor(size_t begin, size_t end, size_t threads,
                        const std::function<void(size_t)>& fn) {
  std::atomic<size_t> next{begin};
  auto work = [&] {
    for (size_t i = next++; i < end; i = next++) fn(i);
  };
  std::vector<std::thread> pool;
  for (size_t t = 1; t < std::min(threads, end > begin ? end - begin : 0); ++t) {
    pool.emplace_back(work);
  }
  work();
  for (auto& thread : pool) thread.join();
}

}  // namespace objdb::database
