#include "tests/support/subprocess.h"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdint>

namespace objdb::testing {
namespace {

using Clock = std::chrono::steady_clock;

void closeFd(int* fd) {
  if (*fd >= 0) close(*fd);
  *fd = -1;
}

}  // namespace

ChildProcess::ChildProcess(const std::vector<std::string>& argv) {
  if (argv.empty()) return;
  // Everything the child needs is prepared before fork(): after it only async-signal-safe calls.
  std::vector<char*> args;
  for (const std::string& arg : argv) args.push_back(const_cast<char*>(arg.c_str()));
  args.push_back(nullptr);
  int out_pipe[2], err_pipe[2];
  if (pipe2(out_pipe, O_CLOEXEC) != 0) return;
  if (pipe2(err_pipe, O_CLOEXEC) != 0) {
    close(out_pipe[0]);
    close(out_pipe[1]);
    return;
  }
  sigset_t none;
  sigemptyset(&none);
  const pid_t pid = fork();
  if (pid == 0) {
    const int null_fd = open("/dev/null", O_RDONLY);
    if (null_fd < 0 || dup2(null_fd, STDIN_FILENO) < 0 || dup2(out_pipe[1], STDOUT_FILENO) < 0 ||
        dup2(err_pipe[1], STDERR_FILENO) < 0) {
      _exit(127);
    }
    pthread_sigmask(SIG_SETMASK, &none, nullptr);
    execv(args[0], args.data());
    _exit(127);
  }
  close(out_pipe[1]);
  close(err_pipe[1]);
  if (pid < 0) {
    close(out_pipe[0]);
    close(err_pipe[0]);
    return;
  }
  pid_ = pid;
  out_fd_ = out_pipe[0];
  err_fd_ = err_pipe[0];
}

ChildProcess::~ChildProcess() {
  if (pid_ > 0 && !reaped_) {
    kill(pid_, SIGKILL);
    reap(/*block=*/true);
  }
  closeFd(&out_fd_);
  closeFd(&err_fd_);
}

bool ChildProcess::pump(std::chrono::milliseconds timeout) {
  pollfd fds[2];
  int count = 0;
  if (out_fd_ >= 0) fds[count++] = {out_fd_, POLLIN, 0};
  if (err_fd_ >= 0) fds[count++] = {err_fd_, POLLIN, 0};
  if (count == 0) return false;
  const int ready = poll(fds, count, static_cast<int>(std::max<int64_t>(0, timeout.count())));
  if (ready < 0 && errno != EINTR) return false;
  for (int i = 0; i < count && ready > 0; ++i) {
    if ((fds[i].revents & (POLLIN | POLLHUP | POLLERR)) == 0) continue;
    char buffer[4096];
    const ssize_t n = read(fds[i].fd, buffer, sizeof(buffer));
    const bool is_out = fds[i].fd == out_fd_;
    if (n > 0) {
      (is_out ? result_.out : result_.err).append(buffer, static_cast<size_t>(n));
    } else if (n == 0 || errno != EINTR) {
      closeFd(is_out ? &out_fd_ : &err_fd_);
    }
  }
  return out_fd_ >= 0 || err_fd_ >= 0;
}

bool ChildProcess::waitForStderr(const std::string& needle, std::chrono::milliseconds timeout) {
  const auto deadline = Clock::now() + timeout;
  while (result_.err.find(needle) == std::string::npos) {
    const auto left =
        std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now());
    if (left.count() <= 0 || !pump(left)) return result_.err.find(needle) != std::string::npos;
  }
  return true;
}

bool ChildProcess::sendSignal(int signal) {
  return pid_ > 0 && !reaped_ && kill(pid_, signal) == 0;
}

void ChildProcess::reap(bool block) {
  if (pid_ <= 0 || reaped_) return;
  int status = 0;
  pid_t done;
  do {
    done = waitpid(pid_, &status, block ? 0 : WNOHANG);
  } while (done < 0 && errno == EINTR);
  if (done != pid_) return;
  reaped_ = true;
  if (WIFEXITED(status)) result_.exit_code = WEXITSTATUS(status);
  if (WIFSIGNALED(status)) result_.term_signal = WTERMSIG(status);
}

ProcessResult ChildProcess::wait(std::chrono::milliseconds timeout) {
  const auto deadline = Clock::now() + timeout;
  auto left = [&deadline] {
    return std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now());
  };
  // The pipes close when the child exits (nobody else holds their write ends: O_CLOEXEC).
  while (left().count() > 0 && pump(left())) {
  }
  reap(/*block=*/false);
  // Streams closed but not exited yet (it closes them just before exiting): poll briefly.
  while (!reaped_ && out_fd_ < 0 && err_fd_ < 0 && left().count() > 0) {
    poll(nullptr, 0, 5);
    reap(/*block=*/false);
  }
  if (!reaped_) {
    result_.timed_out = true;
    kill(pid_, SIGKILL);
    while (pump(std::chrono::milliseconds(1000))) {
    }
    reap(/*block=*/true);
  }
  return result_;
}

ProcessResult runProcess(const std::vector<std::string>& argv, std::chrono::milliseconds timeout) {
  ChildProcess child(argv);
  if (!child.started()) return ProcessResult{};
  return child.wait(timeout);
}

std::string valueAfter(const std::string& text, const std::string& what) {
  const size_t at = text.find(what);
  if (at == std::string::npos) return "(missing)";
  const size_t end = text.find('\n', at);
  return text.substr(at + what.size(), end == std::string::npos ? std::string::npos
                                                                 : end - at - what.size());
}

}  // namespace objdb::testing
