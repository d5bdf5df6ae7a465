// A bounded pool of threads for the server's queries, so that gRPC's callback threads only
// receive and answer calls: unary queries read the store, decode blobs and extract meshes here,
// GetSceneMesh completes and meshes scenes on a pool of its own. A full queue refuses at once
// (RESOURCE_EXHAUSTED, saying how many wait) rather than piling up work no client waits for.
#pragma once

#include <condition_variable>
#include <cstddef>
#include <deque>
#include <functional>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "core/common/status.h"

namespace objdb::server {

class QueryPool {
 public:
  // `name` goes into the refusal's message ("queries", "scene meshes").
  QueryPool(std::string name, int threads, size_t max_queued);
  ~QueryPool();  // stop()
  QueryPool(const QueryPool&) = delete;
  QueryPool& operator=(const QueryPool&) = delete;

  // Queues `job` (run once, on one of the pool's threads). RESOURCE_EXHAUSTED when max_queued
  // jobs wait already, UNAVAILABLE once stopped; the job is then not run.
  Status submit(std::function<void()> job);
  // Jobs waiting (not those running).
  size_t queued() const;
  // Runs every job queued, then joins the threads. Later submits are UNAVAILABLE.
  void stop();

 private:
  void run();

  const std::string name_;
  const size_t max_queued_;
  mutable std::mutex mutex_;
  std::condition_variable changed_;
  std::deque<std::function<void()>> jobs_;
  bool stopping_ = false;
  std::vector<std::thread> threads_;  // last: start after the members above exist
};

}  // namespace objdb::server
