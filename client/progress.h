// A terminal progress bar for long CLI work: "[=====>    ] 120/300  40 fps  ETA 4.5 s".
// Redraws in place on a TTY; prints a line every 10 % otherwise (logs, CI).
#pragma once

#include <chrono>
#include <cstdio>
#include <string>

namespace objdb::cli {

class ProgressBar {
 public:
  ProgressBar(std::string label, size_t total, std::string unit = "frames");
  // Reports `done` items; cheap to call per item.
  void update(size_t done);
  // Final line with the total time.
  void finish();

 private:
  std::string label_;
  size_t total_;
  std::string unit_;
  bool tty_;
  int last_decile_ = -1;
  std::chrono::steady_clock::time_point start_;
  std::chrono::steady_clock::time_point last_draw_;
  size_t done_ = 0;
};

}  // namespace objdb::cli
