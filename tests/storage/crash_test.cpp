// Crashes: a child process inserts, merges and stores raw segments in a loop and reports every
// commit on a pipe; the parent kills it with SIGKILL at a random moment. After every kill the
// file must open, pass SQLite's integrity check and every blob's check, and hold every id the
// child reported as committed, whole. 50 trials here; OBJDB_CRASH_TRIALS=N for a longer run
// (docs/storage.md).
#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <map>
#include <random>
#include <string>
#include <thread>

#include <gtest/gtest.h>

#include "absl/strings/numbers.h"
#include "absl/strings/str_split.h"
#include "core/common/logging.h"
#include "storage/sqlite/sqlite_store.h"
#include "tests/storage/store_fixtures.h"
#include "tests/support/temp_dir.h"

namespace objdb::storage {
namespace {

using objdb::testing::makeRawSegment;
using objdb::testing::makeStoreModel;
using objdb::testing::wholeModel;

void say(int fd, const std::string& line) {
  const std::string text = line + "\n";
  (void)!write(fd, text.data(), text.size());
}

// The child's loop: never returns.
[[noreturn]] void writerLoop(const std::string& path, int fd, uint32_t seed) {
  auto store = SqliteStore::open(path);
  if (!store.ok()) {
    say(fd, "error " + std::string(store.status().message()));
    _exit(2);
  }
  std::mt19937 rng(seed);
  for (int i = 0; i < 100000; ++i) {
    const uint32_t s = rng();
    if (i % 3 == 2) {
      auto ids = (*store)->modelIds();
      if (!ids.ok() || ids->empty()) continue;
      const int64_t target = (*ids)[s % ids->size()];
      auto current = (*store)->model(target);
      if (!current.ok()) _exit(3);
      model::ObjectModel merged = makeStoreModel(s, int((*current)->observations.size()) + 1);
      merged.id = target;
      database::MergeRecord record;
      record.target = target;
      record.source = "segment crash/" + std::to_string(i);
      const size_t observations = merged.observations.size();
      if (!(*store)->replaceModel(std::move(merged), record).ok()) _exit(4);
      say(fd, "merged " + std::to_string(target) + " " + std::to_string(observations));
    } else if (i % 5 == 4) {
      if (!(*store)->putRawSegment(makeRawSegment("crash", s % 50, s)).ok()) _exit(5);
      say(fd, "segment " + std::to_string(s % 50));
    } else {
      auto id = (*store)->addModel(makeStoreModel(s, 1 + int(s % 3)));
      if (!id.ok()) _exit(6);
      say(fd, "added " + std::to_string(*id));
    }
  }
  _exit(0);
}

int trialsFromEnvironment() {
  const char* value = std::getenv("OBJDB_CRASH_TRIALS");
  int n = 0;
  if (value != nullptr && absl::SimpleAtoi(value, &n) && n > 0) return n;
  return 50;
}

TEST(SqliteStoreCrash, EveryReportedCommitSurvivesSigkill) {
  objdb::testing::TempDir dir;
  const std::string path = (dir / "crash.sqlite").string();
  const int trials = trialsFromEnvironment();
  std::mt19937 rng(20261123);
  std::map<int64_t, size_t> committed;  // id → least observation count it must have
  size_t total_lines = 0;
  for (int trial = 0; trial < trials; ++trial) {
    int fds[2];
    ASSERT_EQ(pipe(fds), 0);
    const pid_t pid = fork();
    ASSERT_GE(pid, 0);
    if (pid == 0) {
      close(fds[0]);
      objdb::setLogLevel("warn");
      writerLoop(path, fds[1], uint32_t(trial) * 7919u + 1u);
    }
    close(fds[1]);
    std::this_thread::sleep_for(std::chrono::milliseconds(20 + rng() % 120));
    ASSERT_EQ(kill(pid, SIGKILL), 0);
    int status = 0;
    ASSERT_EQ(waitpid(pid, &status, 0), pid);
    ASSERT_TRUE(WIFSIGNALED(status)) << "child ended on its own (status " << status << ")";
    std::string out;
    char buffer[4096];
    ssize_t n;
    while ((n = read(fds[0], buffer, sizeof buffer)) > 0) out.append(buffer, size_t(n));
    close(fds[0]);
    for (const absl::string_view line : absl::StrSplit(out, '\n', absl::SkipEmpty())) {
      // Each line is one write() below PIPE_BUF, so it arrives whole or not at all.
      const std::vector<std::string> words = absl::StrSplit(line, ' ');
      ASSERT_NE(words[0], "error") << line;
      ++total_lines;
      int64_t id = 0;
      if (words[0] == "added" && absl::SimpleAtoi(words[1], &id)) committed[id] = std::max<size_t>(committed[id], 1);
      size_t observations = 0;
      if (words[0] == "merged" && absl::SimpleAtoi(words[1], &id) &&
          absl::SimpleAtoi(words[2], &observations)) {
        committed[id] = std::max(committed[id], observations);
      }
    }

    auto store = SqliteStore::open(path);
    ASSERT_TRUE(store.ok()) << "trial " << trial << ": " << store.status();
    const auto report = (*store)->check();
    ASSERT_TRUE(report.ok()) << report.status();
    ASSERT_TRUE(report->ok()) << "trial " << trial << ": integrity findings "
                              << report->engine_findings.size() << ", damaged blobs "
                              << report->damaged.size();
    const auto ids = (*store)->modelIds().value();
    for (const auto& [id, observations] : committed) {
      const auto m = (*store)->model(id);
      ASSERT_TRUE(m.ok()) << "trial " << trial << ": committed object " << id << " lost: " << m.status();
      ASSERT_TRUE(wholeModel(**m)) << "trial " << trial << ": object " << id << " is not whole";
      // A later merge may have added more; never fewer than the last reported commit.
      ASSERT_GE((*m)->observations.size(), observations) << "object " << id;
    }
    // The child may have committed one more than it managed to report, never fewer.
    ASSERT_GE(ids.size(), committed.size());
  }
  EXPECT_GT(committed.size(), size_t(trials));  // the children got real work done
  std::printf("%d kills, %zu commits reported, %zu objects checked after every kill\n", trials,
              total_lines, committed.size());
}

}  // namespace
}  // namespace objdb::storage
