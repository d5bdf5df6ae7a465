#include "server/query_pool.h"

#include <atomic>
#include <chrono>
#include <future>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace objdb::server {
namespace {

using ::testing::HasSubstr;

// A gate the pool's jobs wait at until the test opens it.
struct Gate {
  std::promise<void> opened;
  std::shared_future<void> open = opened.get_future().share();
};

TEST(QueryPool, AFullQueueRefusesAtOnceAndRunsWhatItTook) {
  Gate gate;
  std::atomic<int> ran{0};
  std::promise<void> started;
  QueryPool pool("queries", 1, 2);
  // The pool's one thread waits at the gate; two more jobs wait in the queue.
  ASSERT_TRUE(pool.submit([&] {
    started.set_value();
    gate.open.wait();
    ++ran;
  }).ok());
  started.get_future().wait();
  ASSERT_TRUE(pool.submit([&] { ++ran; }).ok());
  ASSERT_TRUE(pool.submit([&] { ++ran; }).ok());
  EXPECT_EQ(pool.queued(), 2u);
  const Status refused = pool.submit([&] { ran += 100; });
  EXPECT_EQ(refused.code(), absl::StatusCode::kResourceExhausted);
  EXPECT_THAT(std::string(refused.message()), HasSubstr("busy: 2 queries wait"));
  gate.opened.set_value();
  pool.stop();
  EXPECT_EQ(ran.load(), 3);  // the refused job never ran
  const Status stopped = pool.submit([&] { ran += 100; });
  EXPECT_EQ(stopped.code(), absl::StatusCode::kUnavailable);
  EXPECT_EQ(ran.load(), 3);
}

TEST(QueryPool, JobsRunOnThePoolsThreadsNotTheCallers) {
  QueryPool pool("queries", 3, 100);
  std::mutex mutex;
  std::vector<std::thread::id> ids;
  std::atomic<int> done{0};
  for (int i = 0; i < 30; ++i) {
    ASSERT_TRUE(pool.submit([&] {
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
      std::lock_guard lock(mutex);
      ids.push_back(std::this_thread::get_id());
      ++done;
    }).ok());
  }
  pool.stop();  // runs every queued job first
  EXPECT_EQ(done.load(), 30);
  for (const auto& id : ids) EXPECT_NE(id, std::this_thread::get_id());
}

}  // namespace
}  // namespace objdb::server
