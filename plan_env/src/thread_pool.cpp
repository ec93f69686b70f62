#include "topo_planner/plan_env/thread_pool.h"

#include <cassert>

namespace topo_planner {

ThreadPool::ThreadPool(int num_threads) {
  assert(num_threads >= 1);
  for (int w = 1; w < num_threads; ++w) threads_.emplace_back([this, w] { workerLoop(w); });
}

ThreadPool::~ThreadPool() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  start_cv_.notify_all();
  for (auto& t : threads_) t.join();
}

void ThreadPool::runTasks(uint32_t call, int num_tasks, const Job& job, int worker) {
  uint64_t claim = claim_.load();
  for (;;) {
    // A task is claimed for its own call only: a worker that woke after its call ended (and maybe
    // after the next one began) claims nothing, so `job` is never run once its call has returned.
    if (uint32_t(claim >> 32) != call || int(uint32_t(claim)) >= num_tasks) return;
    if (!claim_.compare_exchange_weak(claim, claim + 1)) continue;
    try {
      job(int(uint32_t(claim)), worker);
    } catch (...) {  // kept for the caller; the other tasks still run, so nobody waits forever
      std::lock_guard<std::mutex> lock(mutex_);
      if (!error_) error_ = std::current_exception();
    }
    if (done_.fetch_add(1) + 1 == num_tasks) {
      std::lock_guard<std::mutex> lock(mutex_);  // the caller is waiting or about to check done_
      done_cv_.notify_one();
    }
    claim = claim_.load();
  }
}

void ThreadPool::parallelFor(int num_tasks, const Job& fn) {
  if (num_tasks <= 0) return;
  std::lock_guard<std::mutex> call_lock(call_mutex_);
  if (threads_.empty() || num_tasks == 1) {  // inline; an exception propagates directly
    for (int t = 0; t < num_tasks; ++t) fn(t, 0);
    return;
  }
  uint32_t call;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    call = ++call_;
    job_ = &fn;
    num_tasks_ = num_tasks;
    error_ = nullptr;
    done_.store(0);
    claim_.store(uint64_t(call) << 32);
  }
  start_cv_.notify_all();
  runTasks(call, num_tasks, fn, 0);
  // Wait for the tasks the workers claimed, not for the workers: one still asleep has claimed none,
  // and waking a sleeping thread takes 0.1-20 ms on a loaded or virtual machine.
  std::unique_lock<std::mutex> lock(mutex_);
  done_cv_.wait(lock, [&] { return done_.load() == num_tasks; });
  job_ = nullptr;
  if (error_) {
    std::exception_ptr e = error_;
    error_ = nullptr;
    lock.unlock();
    std::rethrow_exception(e);
  }
}

void ThreadPool::workerLoop(int worker) {
  uint32_t seen = 0;
  for (;;) {
    const Job* job = nullptr;
    int num_tasks = 0;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      start_cv_.wait(lock, [&] { return stop_ || call_ != seen; });
      if (stop_) return;
      seen = call_;
      job = job_;  // null when that call has already ended
      num_tasks = num_tasks_;
    }
    if (job) runTasks(seen, num_tasks, *job, worker);
  }
}

}  // namespace topo_planner
