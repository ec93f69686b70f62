#pragma once
// A fixed pool of worker threads, created once by the object that owns it (STYLE.md: no thread per
// call). parallelFor blocks until every task has run; the calling thread works too, and it never
// waits for a worker that has not woken up yet: it takes that worker's tasks itself.

#include <atomic>
#include <cstdint>
#include <condition_variable>
#include <exception>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace topo_planner {

class ThreadPool {
 public:
  /// num_threads >= 1 workers in all, the caller included (so num_threads - 1 threads are started).
  explicit ThreadPool(int num_threads);
  ~ThreadPool();
  ThreadPool(const ThreadPool&) = delete;
  ThreadPool& operator=(const ThreadPool&) = delete;

  int size() const { return int(threads_.size()) + 1; }

  /// Runs fn(task, worker) for every task in [0, num_tasks); worker is in [0, size()) and no two
  /// tasks run on the same worker at once, so per-worker scratch indexed by it needs no lock.
  /// Concurrent calls on one pool are serialised. If tasks throw, the remaining tasks still run and
  /// the first exception is rethrown to the caller once all tasks are done.
  using Job = std::function<void(int task, int worker)>;
  void parallelFor(int num_tasks, const Job& fn);

 private:
  void workerLoop(int worker);
  void runTasks(uint32_t call, int num_tasks, const Job& job, int worker);

  std::vector<std::thread> threads_;
  std::mutex call_mutex_;  // one parallelFor at a time
  std::mutex mutex_;
  std::condition_variable start_cv_;
  std::condition_variable done_cv_;
  // The current call, under mutex_: its number, job (null once it has returned) and task count.
  uint32_t call_ = 0;
  const Job* job_ = nullptr;
  int num_tasks_ = 0;
  std::atomic<uint64_t> claim_{0};  // (call << 32) | next task of that call
  std::atomic<int> done_{0};        // tasks of the current call finished
  std::exception_ptr error_;  // first exception of the current parallelFor
  bool stop_ = false;
};

}  // namespace topo_planner
