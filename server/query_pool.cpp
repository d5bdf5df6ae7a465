#include "server/query_pool.h"

#include "absl/strings/str_format.h"

namespace objdb::server {

QueryPool::QueryPool(std::string name, int threads, size_t max_queued)
    : name_(std::move(name)), max_queued_(max_queued) {
  for (int i = 0; i < std::max(1, threads); ++i) threads_.emplace_back([this] { run(); });
}

QueryPool::~QueryPool() { stop(); }

Status QueryPool::submit(std::function<void()> job) {
  {
    std::lock_guard lock(mutex_);
    if (stopping_) {
      return absl::UnavailableError(absl::StrFormat("the server is stopping: no new %s", name_));
    }
    if (jobs_.size() >= max_queued_) {
      return absl::ResourceExhaustedError(absl::StrFormat(
          "the server is busy: %d %s wait already (its limit); retry later", jobs_.size(), name_));
    }
    jobs_.push_back(std::move(job));
  }
  changed_.notify_one();
  return absl::OkStatus();
}

size_t QueryPool::queued() const {
  std::lock_guard lock(mutex_);
  return jobs_.size();
}

void QueryPool::stop() {
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
  }
  changed_.notify_all();
  for (std::thread& t : threads_) {
    if (t.joinable()) t.join();
  }
}

void QueryPool::run() {
  for (;;) {
    std::function<void()> job;
    {
      std::unique_lock lock(mutex_);
      changed_.wait(lock, [this] { return stopping_ || !jobs_.empty(); });
      if (jobs_.empty()) return;  // stopping, and everything queued ran
      job = std::move(jobs_.front());
      jobs_.pop_front();
    }
    job();
  }
}

}  // namespace objdb::server
