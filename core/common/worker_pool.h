// A fixed set of worker threads for fork-join loops that run many times a second (one TSDF
// integration per frame runs three of them): starting a thread costs ~45 µs on a small VM, a
// wake-up of a parked worker a fraction of that. The caller works too, as worker 0.
#pragma once

#include <condition_variable>
#include <cstddef>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace objdb {

class WorkerPool {
 public:
  // `threads` ≥ 1 in all, counting the caller: threads − 1 are started.
  explicit WorkerPool(int threads);
  ~WorkerPool();
  WorkerPool(const WorkerPool&) = delete;
  WorkerPool& operator=(const WorkerPool&) = delete;

  int threads() const { return int(workers_.size()) + 1; }

  // Runs fn(worker) for worker = 0 .. n − 1 (n = min(workers, threads())) at once, worker 0 on
  // the calling thread, and returns when all have returned. Calls from several threads take
  // turns. fn must not throw and must not call run() on the same pool.
  void run(int workers, const std::function<void(int worker)>& fn);

 private:
  void loop(int worker);

  std::vector<std::thread> workers_;
  std::mutex run_mutex_;  // one run() at a time
  std::mutex mutex_;
  std::condition_variable start_, done_;
  const std::function<void(int)>* job_ = nullptr;
  int job_workers_ = 0;
  size_t generation_ = 0;
  int pending_ = 0;
  bool stop_ = false;
};

// pool->run(workers, fn), or fn(0) alone without a pool.
inline void runOnPool(WorkerPool* pool, int workers, const std::function<void(int worker)>& fn) {
  if (pool != nullptr) {
    pool->run(workers, fn);
  } else {
    fn(0);
  }
}

}  // namespace objdb
