// Running the project's binaries from tests: start with captured stdout/stderr, wait for a line,
// send signals, reap with a time limit. Every wait is bounded; a child still running at the end
// of a deadline or at destruction is killed with SIGKILL.
#pragma once

#include <sys/types.h>

#include <chrono>
#include <string>
#include <vector>

namespace objdb::testing {

struct ProcessResult {
  int exit_code = -1;      // exit status when the process exited, else -1
  int term_signal = 0;     // signal that ended it, 0 when it exited
  bool timed_out = false;  // killed by us because the deadline passed
  std::string out;         // everything written to stdout
  std::string err;         // everything written to stderr
};

class ChildProcess {
 public:
  // Starts argv[0] (a path, not searched in PATH) with the given arguments, stdin from
  // /dev/null and the default signal mask. started() says whether fork/exec worked.
  explicit ChildProcess(const std::vector<std::string>& argv);
  ~ChildProcess();
  ChildProcess(const ChildProcess&) = delete;
  ChildProcess& operator=(const ChildProcess&) = delete;

  bool started() const { return pid_ > 0; }
  pid_t pid() const { return pid_; }

  // Collects output until `needle` occurs in stderr, both streams close or `timeout` passes.
  bool waitForStderr(const std::string& needle, std::chrono::milliseconds timeout);
  // Reads the output that is there now, waiting at most `timeout` for some: a long-lived child
  // that logs must be read from now and then, or it blocks on a full pipe.
  void collect(std::chrono::milliseconds timeout = std::chrono::milliseconds(0)) {
    (void)pump(timeout);
  }
  // Sends `signal` to the child; false if it is no longer running.
  bool sendSignal(int signal);
  // Collects output until the child exits (killing it after `timeout`) and reaps it.
  ProcessResult wait(std::chrono::milliseconds timeout);

  const std::string& stdoutText() const { return result_.out; }
  const std::string& stderrText() const { return result_.err; }

 private:
  // Reads whatever is available within `timeout`; false once both streams are closed.
  bool pump(std::chrono::milliseconds timeout);
  void reap(bool block);

  pid_t pid_ = -1;
  int out_fd_ = -1;
  int err_fd_ = -1;
  bool reaped_ = false;
  ProcessResult result_;
};

// Runs a command to completion (at most `timeout`, then SIGKILL) and returns its output.
ProcessResult runProcess(const std::vector<std::string>& argv,
                         std::chrono::milliseconds timeout = std::chrono::seconds(60));

// The rest of the line of `text` after the first occurrence of `what` (a command's report line
// "label   value"); "(missing)" when `what` does not occur.
std::string valueAfter(const std::string& text, const std::string& what);

}  // namespace objdb::testing
