// One worker thread running jobs in the order they were queued: the server's object database
// (Algorithm 1 is one writer's sequence of inserts) runs on one, so gRPC threads never wait for
// matching. No producer ever waits on it: a session's frame worker looks at pending() and puts
// extraction off while the database is behind (ObjectDatabaseService::processFrame).
#pragma once

#include <condition_variable>
#include <cstddef>
#include <deque>
#include <functional>
#include <mutex>
#include <thread>

namespace objdb::server {

class JobQueue {
 public:
  JobQueue();
  // Runs every queued job, then stops the thread.
  ~JobQueue();
  JobQueue(const JobQueue&) = delete;
  JobQueue& operator=(const JobQueue&) = delete;

  // Queues the job at once, whatever the queue holds.
  void push(std::function<void()> job);
  // Jobs queued or running.
  size_t pending() const;

 private:
  void run();

  mutable std::mutex mutex_;
  std::condition_variable changed_;
  std::deque<std::function<void()>> jobs_;
  bool running_job_ = false;
  bool stopping_ = false;
  std::thread thread_;  // last: starts after the members above exist
};

}  // namespace objdb::server
