// SIGINT/SIGTERM handling for the server binary without work in a signal handler: the signals are
// blocked in every thread and a dedicated thread takes them with sigwait() (gRPC's Shutdown takes
// locks, so calling it from a handler can deadlock: grpc/grpc#24884).
#pragma once

#include <condition_variable>
#include <mutex>
#include <thread>

namespace objdb {

// Blocks SIGINT and SIGTERM in the calling thread (threads created afterwards inherit the mask)
// and restores their default action in case the parent ignored them.
// Call first thing in main(), before anything starts a thread (gRPC does). Returns false if the
// mask could not be set.
bool blockShutdownSignals();

// Waits for SIGINT/SIGTERM on its own thread. The first signal makes waitForRequest() return; a
// second one exits the process at once with 128 + signal (for a drain that takes too long).
class ShutdownSignalWatcher {
 public:
  ShutdownSignalWatcher();  // requires blockShutdownSignals() to have run
  ~ShutdownSignalWatcher();
  ShutdownSignalWatcher(const ShutdownSignalWatcher&) = delete;
  ShutdownSignalWatcher& operator=(const ShutdownSignalWatcher&) = delete;

  // Blocks until the first signal arrives; returns its number.
  int waitForRequest();

 private:
  void run();

  std::mutex mutex_;
  std::condition_variable cv_;
  int signal_ = 0;         // first signal received, 0 = none yet
  bool stopping_ = false;  // set by the destructor before it wakes the thread
  std::thread thread_;
};

}  // namespace objdb
