#include "core/common/worker_pool.h"

#include <atomic>
#include <mutex>
#include <set>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

namespace objdb {
namespace {

TEST(WorkerPool, RunsEveryWorkerOnceAndTheCallerIsWorkerZero) {
  for (int threads : {1, 2, 4}) {
    WorkerPool pool(threads);
    EXPECT_EQ(pool.threads(), threads);
    for (int round = 0; round < 200; ++round) {
      std::vector<std::atomic<int>> calls(static_cast<size_t>(threads));
      std::thread::id worker_zero;
      pool.run(threads, [&](int w) {
        calls[size_t(w)].fetch_add(1);
        if (w == 0) worker_zero = std::this_thread::get_id();
      });
      for (int w = 0; w < threads; ++w) ASSERT_EQ(calls[size_t(w)].load(), 1) << w;
      ASSERT_EQ(worker_zero, std::this_thread::get_id());
    }
  }
}

TEST(WorkerPool, AskingForFewerOrMoreWorkersClampsToThePool) {
  WorkerPool pool(4);
  std::atomic<int> calls{0}, highest{-1};
  pool.run(2, [&](int w) {
    calls.fetch_add(1);
    int h = highest.load();
    while (w > h && !highest.compare_exchange_weak(h, w)) {
    }
  });
  EXPECT_EQ(calls.load(), 2);
  EXPECT_EQ(highest.load(), 1);
  calls = 0;
  pool.run(16, [&](int) { calls.fetch_add(1); });
  EXPECT_EQ(calls.load(), 4);
  calls = 0;
  pool.run(0, [&](int w) { calls.fetch_add(w == 0 ? 1 : 100); });
  EXPECT_EQ(calls.load(), 1);
}

TEST(WorkerPool, WorkersRunAtTheSameTime) {
  // Each worker waits for all the others: this finishes only if they run concurrently.
  WorkerPool pool(3);
  std::atomic<int> arrived{0};
  pool.run(3, [&](int) {
    arrived.fetch_add(1);
    while (arrived.load() < 3) std::this_thread::yield();
  });
  EXPECT_EQ(arrived.load(), 3);
}

TEST(WorkerPool, CallersOnSeveralThreadsTakeTurns) {
  WorkerPool pool(2);
  std::atomic<int> inside{0}, most{0}, total{0};
  auto caller = [&] {
    for (int i = 0; i < 300; ++i) {
      pool.run(2, [&](int) {
        const int now = inside.fetch_add(1) + 1;
        int m = most.load();
        while (now > m && !most.compare_exchange_weak(m, now)) {
        }
        total.fetch_add(1);
        inside.fetch_sub(1);
      });
    }
  };
  std::thread a(caller), b(caller);
  a.join();
  b.join();
  EXPECT_EQ(total.load(), 2 * 300 * 2);
  EXPECT_LE(most.load(), 2);  // never two runs' workers at once
}

}  // namespace
}  // namespace objdb
