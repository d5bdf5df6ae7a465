#include "server/shutdown_signals.h"

#include <pthread.h>
#include <signal.h>
#include <string.h>

#include <cstdlib>
#include <string>

#include "absl/strings/str_cat.h"
#include "core/common/logging.h"

namespace objdb {
namespace {

sigset_t shutdownSignals() {
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, SIGINT);
  sigaddset(&set, SIGTERM);
  return set;
}

std::string signalName(int signal_number) {
  const char* abbrev = sigabbrev_np(signal_number);
  return abbrev != nullptr ? absl::StrCat("SIG", abbrev) : absl::StrCat("signal ", signal_number);
}

}  // namespace

bool blockShutdownSignals() {
  const sigset_t set = shutdownSignals();
  if (pthread_sigmask(SIG_BLOCK, &set, nullptr) != 0) return false;
  // A parent may have left them ignored (a background job of a non-interactive shell ignores
  // SIGINT); what sigwait() does with ignored signals is unspecified, so restore the default
  // action. While blocked, the default action never runs: sigwait() takes the signal.
  return signal(SIGINT, SIG_DFL) != SIG_ERR && signal(SIGTERM, SIG_DFL) != SIG_ERR;
}

ShutdownSignalWatcher::ShutdownSignalWatcher() : thread_([this] { run(); }) {}

ShutdownSignalWatcher::~ShutdownSignalWatcher() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
  }
  // Wake the sigwait() with a signal aimed at that thread only; `stopping_` tells it to leave.
  pthread_kill(thread_.native_handle(), SIGTERM);
  thread_.join();
}

int ShutdownSignalWatcher::waitForRequest() {
  std::unique_lock<std::mutex> lock(mutex_);
  cv_.wait(lock, [this] { return signal_ != 0; });
  return signal_;
}

void ShutdownSignalWatcher::run() {
  const sigset_t set = shutdownSignals();
  for (;;) {
    int signal_number = 0;
    if (sigwait(&set, &signal_number) != 0) continue;
    std::unique_lock<std::mutex> lock(mutex_);
    if (stopping_) return;
    if (signal_ == 0) {
      signal_ = signal_number;
      lock.unlock();
      logger("server")->info("received {}, shutting down (send it again to exit at once)",
                             signalName(signal_number));
      cv_.notify_all();
    } else {
      logger("server")->warn("received {} again, exiting without draining",
                             signalName(signal_number));
      std::_Exit(128 + signal_number);
    }
  }
}

}  // namespace objdb
