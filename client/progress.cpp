#include "client/progress.h"

#include <unistd.h>

#include <algorithm>

namespace objdb::cli {

ProgressBar::ProgressBar(std::string label, size_t total, std::string unit)
    : label_(std::move(label)),
      total_(std::max<size_t>(total, 1)),
      unit_(std::move(unit)),
      tty_(isatty(fileno(stderr)) != 0),
      start_(std::chrono::steady_clock::now()),
      last_draw_(start_) {}

void ProgressBar::update(size_t done) {
  done_ = done;
  const auto now = std::chrono::steady_clock::now();
  const double elapsed = std::chrono::duration<double>(now - start_).count();
  const double rate = elapsed > 0 ? double(done) / elapsed : 0.0;
  const double eta = rate > 0 ? double(total_ - std::min(done, total_)) / rate : 0.0;
  if (tty_) {
    if (done < total_ && now - last_draw_ < std::chrono::milliseconds(100)) return;
    last_draw_ = now;
    constexpr int kWidth = 30;
    const int filled = int(kWidth * std::min(done, total_) / total_);
    std::string bar(size_t(filled), '=');
    if (filled < kWidth) bar += '>' + std::string(size_t(kWidth - filled - 1), ' ');
    std::fprintf(stderr, "\r%s [%s] %zu/%zu  %.1f %s/s  ETA %.1f s   ", label_.c_str(),
                 bar.c_str(), done, total_, rate, unit_.c_str(), eta);
    std::fflush(stderr);
    return;
  }
  const int decile = int(10 * std::min(done, total_) / total_);
  if (decile != last_decile_) {
    last_decile_ = decile;
    std::fprintf(stderr, "%s %zu/%zu (%d%%)  %.1f %s/s  ETA %.1f s\n", label_.c_str(), done,
                 total_, decile * 10, rate, unit_.c_str(), eta);
  }
}

void ProgressBar::finish() {
  const double elapsed =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  if (tty_) std::fprintf(stderr, "\r\033[K");
  std::fprintf(stderr, "%s done: %zu %s in %.1f s (%.1f %s/s)\n", label_.c_str(), done_,
               unit_.c_str(), elapsed, elapsed > 0 ? double(done_) / elapsed : 0.0, unit_.c_str());
}

}  // namespace objdb::cli
