#pragma once
// A fixed pool of worker threads, created once by the object that owns it (STYLE.md: no thread per
// call). parallelFor blocks until every task has run; the calling thread works too.

#include <atomic>
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
  /// the first exception is rethrown to the caller once all workers are done.
  void parallelFor(int num_tasks, const std::function<void(int task, int worker)>& fn);

 private:
  void workerLoop(int worker);
  void runTasks(int worker);

  std::vector<std::thread> threads_;
  std::mutex call_mutex_;  // one parallelFor at a time
  std::mutex mutex_;
  std::condition_variable start_cv_;
  std::condition_variable done_cv_;
  const std::function<void(int, int)>* job_ = nullptr;
  int num_tasks_ = 0;
  std::atomic<int> next_task_{0};
  int busy_workers_ = 0;
  std::exception_ptr error_;  // first exception of the current parallelFor
  uint64_t generation_ = 0;
  bool stop_ = false;
};

}  // namespace topo_planner
