#include <gtest/gtest.h>

#include <atomic>
#include <stdexcept>
#include <thread>

#include "topo_planner/plan_env/thread_pool.h"

namespace topo_planner {
namespace {

TEST(ThreadPool, RunsEveryTaskOnceOnAValidWorker) {
  for (int threads : {1, 2, 4}) {
    ThreadPool pool(threads);
    EXPECT_EQ(pool.size(), threads);
    for (int round = 0; round < 200; ++round) {
      const int n = round % 37;
      std::vector<std::atomic<int>> hits(static_cast<size_t>(n));
      std::atomic<bool> bad_worker{false};
      pool.parallelFor(n, [&](int task, int worker) {
        hits[size_t(task)].fetch_add(1);
        if (worker < 0 || worker >= threads) bad_worker = true;
      });
      for (auto& h : hits) ASSERT_EQ(h.load(), 1);
      ASSERT_FALSE(bad_worker.load());
    }
  }
}

TEST(ThreadPool, WorkerIndexIsExclusive) {
  ThreadPool pool(3);
  std::vector<std::atomic<int>> in_use(3);
  std::atomic<bool> overlap{false};
  std::atomic<int> sum{0};
  for (int round = 0; round < 50; ++round) {
    pool.parallelFor(64, [&](int task, int worker) {
      if (in_use[size_t(worker)].fetch_add(1) != 0) overlap = true;
      sum += task;
      in_use[size_t(worker)].fetch_sub(1);
    });
  }
  EXPECT_FALSE(overlap.load());
  EXPECT_EQ(sum.load(), 50 * (63 * 64 / 2));
}

// Back-to-back calls with their state on the stack: a worker that wakes late must not run a task
// of a call that has returned (it would count in the next call's hits, or touch a dead frame under
// AddressSanitizer). Run under ThreadSanitizer too.
TEST(ThreadPool, NoTaskRunsAfterItsCallReturned) {
  ThreadPool pool(3);
  for (int round = 0; round < 20000; ++round) {
    const int n = 2 + round % 4;
    std::atomic<bool> open{true};
    std::atomic<int> hits{0}, late{0};
    pool.parallelFor(n, [&](int, int) {
      if (!open.load()) late.fetch_add(1);
      hits.fetch_add(1);
    });
    open = false;
    ASSERT_EQ(hits.load(), n) << "round " << round;
    ASSERT_EQ(late.load(), 0) << "round " << round;
  }
}

TEST(ThreadPool, ConcurrentCallersAreSerialised) {
  ThreadPool pool(2);
  std::atomic<int> total{0};
  std::vector<std::thread> callers;
  for (int c = 0; c < 4; ++c)
    callers.emplace_back([&] {
      for (int r = 0; r < 100; ++r) pool.parallelFor(10, [&](int, int) { total.fetch_add(1); });
    });
  for (auto& t : callers) t.join();
  EXPECT_EQ(total.load(), 4 * 100 * 10);
}

TEST(ThreadPool, ExceptionsReachTheCallerAfterAllTasks) {
  ThreadPool pool(2);
  std::atomic<int> ran{0};
  EXPECT_THROW(pool.parallelFor(50,
                                [&](int task, int) {
                                  ran.fetch_add(1);
                                  if (task % 7 == 3) throw std::runtime_error("task failed");
                                }),
               std::runtime_error);
  EXPECT_EQ(ran.load(), 50);
  // The pool is still usable.
  std::atomic<int> again{0};
  pool.parallelFor(20, [&](int, int) { again.fetch_add(1); });
  EXPECT_EQ(again.load(), 20);
}

}  // namespace
}  // namespace topo_planner
