#pragma once
/// \file A small persistent fork-join thread pool for the engine's per-sample work.
///
/// `run(count, task)` calls `task(item, worker)` once for every item in [0, count) and returns
/// when all calls have finished; the calling thread takes items too (it is worker 0). Items are
/// claimed dynamically, so which worker runs an item varies from run to run: a task must write
/// only to outputs owned by its item (and to scratch owned by its worker), which is how the
/// engine keeps every result independent of the number of threads.
///
/// The engine forks once per time step, so the hand-off must be cheap and must not depend on
/// every worker being awake: an item is claimed by one compare-and-swap on (run, next item),
/// and a run ends when its items are done, so the caller never waits for a worker that has
/// not started (on a busy machine it simply does the items itself). Idle workers spin for a
/// short while (`pause`, then yielding the core) before they block on a condition variable,
/// and a run wakes sleeping workers only when there are any. No run allocates.
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <exception>
#include <mutex>
#include <string>
#include <system_error>
#include <thread>
#include <vector>

#include "sbptt/core/error.hpp"
#include "sbptt/core/types.hpp"

namespace sbptt::detail {

/// Hint to the core that this thread is busy-waiting.
inline void cpu_relax() {
#if defined(__x86_64__) || defined(__i386__)
  __builtin_ia32_pause();
#endif
}

/// One turn of a busy wait: `pause` at first, then yield the core, because on a machine with
/// fewer free cores than threads the thread waited for may have been preempted. A wait takes
/// a few microseconds, less than waking a sleeping thread.
inline void back_off(int& turns) {
  if (++turns < 2048) {
    cpu_relax();
  } else {
    std::this_thread::yield();
  }
}

/// What to say when the system started `started` of `asked` threads (the caller's included) and
/// then refused one for `reason`.
[[nodiscard]] inline std::string threads_not_started(Index started, Index asked,
                                                     const char* reason) {
  return concat("the system started ", started, " of the ", asked,
                " threads asked for (the caller's included): ", reason,
                "; expected a thread count within the process's limits (ulimit -u, a "
                "container's or Slurm's pids limit, ulimit -v)");
}

/// Fork-join pool of `threads − 1` background workers plus the calling thread.
class ThreadPool {
public:
  /// \param threads total threads of a run, ≥ 1 (1: `run` executes inline, no worker exists).
  /// Throws `ResourceError` when the system will not start them all (a process limit such as
  /// ulimit -u or a container's pids limit, or ulimit -v), after stopping those it started.
  explicit ThreadPool(Index threads) {
    require(threads >= 1, "ThreadPool: threads = ", threads, "; expected at least 1");
    workers_.reserve(static_cast<std::size_t>(threads - 1));
    for (Index w = 1; w < threads; ++w) {
      try {
        workers_.emplace_back([this, w] { work(w); });
      } catch (const std::system_error& e) {
        // The destructor does not run for a constructor that throws; joinable threads left
        // behind would terminate the program, or hang it in the condition variable's end.
        stop_and_join();
        throw ResourceError(threads_not_started(w, threads, e.what()));
      } catch (...) {  // std::thread allocates its state first: bad_alloc under ulimit -v
        stop_and_join();
        throw;
      }
    }
  }

  ThreadPool(const ThreadPool&) = delete;
  ThreadPool& operator=(const ThreadPool&) = delete;

  ~ThreadPool() { stop_and_join(); }

  /// Threads taking part in a run, the caller included.
  [[nodiscard]] Index threads() const { return static_cast<Index>(workers_.size()) + 1; }

  /// Calls `task(item, worker)` for every item in [0, count), worker ∈ [0, threads()). Not
  /// reentrant: a task must not call `run` on the same pool. The first exception thrown by a
  /// task is rethrown here after every item has been attempted.
  template <class Task>
  void run(Index count, Task& task) {
    if (count <= 0) return;
    if (workers_.empty() || count == 1) {
      for (Index i = 0; i < count; ++i) task(i, 0);
      return;
    }
    start(count, task);
    finish(count);
  }

  /// Offers the items of `task` to the other threads while the calling thread runs
  /// `foreground()`; then the caller takes any item still unclaimed and returns when all are
  /// done. So an item never runs on the calling thread while `foreground` does, and `foreground`
  /// always runs on the calling thread (its thread-local buffers are the caller's). An item
  /// that waits for `foreground` must therefore stop waiting once `foreground` has returned or
  /// thrown. The first exception, `foreground`'s before any item's, is rethrown here after
  /// every item has been attempted.
  template <class Task, class Foreground>
  void run_beside(Index count, Task& task, Foreground&& foreground) {
    std::exception_ptr failure;
    auto keep_first = [&](auto&& work) {
      try {
        work();
      } catch (...) {
        if (!failure) failure = std::current_exception();
      }
    };
    const bool beside = count > 0 && !workers_.empty();
    if (beside) start(count, task);
    keep_first(foreground);
    if (beside) {
      keep_first([&] { finish(count); });  // items may read what `foreground` left: wait first
    } else {
      for (Index i = 0; i < count; ++i) keep_first([&] { task(i, 0); });
    }
    if (failure) std::rethrow_exception(failure);
  }

private:
  static constexpr int kIndexBits = 32;
  static constexpr std::uint64_t kIndexMask = (std::uint64_t{1} << kIndexBits) - 1;

  /// Publishes the items [0, count) of `task` as a new run.
  ///
  /// The finished run is closed first (a generation of its own whose next item is past any
  /// count). A worker that has just done its last item may still hold the old state and be
  /// about to read the run's size: without the close it could read the new size, still claim
  /// an item with the old state, and run the new task before it is published (an item run
  /// twice, a run counted done too early). With it, the old state is gone before any new
  /// parameter is written, and a worker that reads one (acquire, against these release
  /// stores) is ordered after the close, so its claim fails.
  template <class Task>
  void start(Index count, Task& task) {
    const std::uint64_t closed = (state_.load(std::memory_order_relaxed) >> kIndexBits) + 1;
    state_.store((closed << kIndexBits) | kIndexMask, std::memory_order_seq_cst);
    call_.store([](void* context, Index item, Index worker) {
      (*static_cast<Task*>(context))(item, worker);
    }, std::memory_order_release);
    context_.store(&task, std::memory_order_release);
    count_.store(count, std::memory_order_release);
    done_.store(0, std::memory_order_relaxed);
    error_ = nullptr;
    publish();
  }

  /// Takes the run's unclaimed items on the calling thread (worker 0), waits for all `count`,
  /// and rethrows the first exception of an item.
  void finish(Index count) {
    drain(0);
    wait_until([&] { return done_.load(std::memory_order_acquire) == count; });
    if (error_) std::rethrow_exception(error_);
  }

  /// Starts a new run (item 0 of a new generation) and wakes sleepers, if any.
  void publish() {
    const std::uint64_t generation = (state_.load(std::memory_order_relaxed) >> kIndexBits) + 1;
    state_.store(generation << kIndexBits, std::memory_order_seq_cst);
    if (sleepers_.load(std::memory_order_seq_cst) > 0) {
      { const std::lock_guard<std::mutex> lock(mutex_); }
      wake_.notify_all();
    }
  }

  /// Busy-waits for `ready`: a few thousand `pause`s, then yielding the core (the machine may
  /// have fewer free cores than threads). False if `yield_for` ran out first.
  template <class Ready>
  static bool wait_until(Ready&& ready, std::chrono::microseconds yield_for =
                                            std::chrono::microseconds::max()) {
    for (int spin = 0; spin < 2048; ++spin) {
      if (ready()) return true;
      cpu_relax();
    }
    const auto start = std::chrono::steady_clock::now();
    while (!ready()) {
      if (yield_for != std::chrono::microseconds::max() &&
          std::chrono::steady_clock::now() - start >= yield_for)
        return false;
      std::this_thread::yield();
    }
    return true;
  }

  /// Claims and runs items of the generation in `state_` until none is left.
  void drain(Index worker) {
    std::uint64_t seen = state_.load(std::memory_order_acquire);
    for (;;) {
      const auto item = static_cast<Index>(seen & kIndexMask);
      // Read before claiming: a successful claim proves the run had not ended, so these
      // belong to it (`publish` orders them before the state; `start` closes the old state
      // before it overwrites them).
      const auto count = count_.load(std::memory_order_acquire);
      const auto call = call_.load(std::memory_order_acquire);
      void* const context = context_.load(std::memory_order_acquire);
      if (item >= count) return;
      if (!state_.compare_exchange_weak(seen, seen + 1, std::memory_order_acq_rel,
                                        std::memory_order_acquire))
        continue;  // `seen` now holds the current state; a new run is fine too
      try {
        call(context, item, worker);
      } catch (...) {
        const std::lock_guard<std::mutex> lock(mutex_);
        if (!error_) error_ = std::current_exception();
      }
      done_.fetch_add(1, std::memory_order_release);
      seen = state_.load(std::memory_order_acquire);
    }
  }

  void stop_and_join() {
    stop_.store(true, std::memory_order_relaxed);
    // The wake-up is a new generation: with the last run's size left in place, a worker still
    // in `drain` would claim its items again and call a task whose captures may be gone.
    count_.store(0, std::memory_order_release);
    publish();
    for (auto& worker : workers_) worker.join();
  }

  void work(Index worker) {
    std::uint64_t generation = 0;
    const auto fresh = [&] {
      return (state_.load(std::memory_order_acquire) >> kIndexBits) != generation;
    };
    for (;;) {
      if (!wait_until(fresh, std::chrono::microseconds(200))) {
        std::unique_lock<std::mutex> lock(mutex_);
        sleepers_.fetch_add(1, std::memory_order_seq_cst);
        wake_.wait(lock, fresh);
        sleepers_.fetch_sub(1, std::memory_order_relaxed);
      }
      generation = state_.load(std::memory_order_acquire) >> kIndexBits;
      if (stop_.load(std::memory_order_acquire)) return;
      drain(worker);
    }
  }

  std::vector<std::thread> workers_;
  std::mutex mutex_;
  std::condition_variable wake_;
  std::atomic<std::uint64_t> state_{0};  ///< generation << 32 | next item of the current run
  std::atomic<int> sleepers_{0};
  std::atomic<bool> stop_{false};
  std::atomic<Index> done_{0};
  // The current run, written before `publish`.
  std::atomic<void (*)(void*, Index, Index)> call_{nullptr};
  std::atomic<void*> context_{nullptr};
  std::atomic<Index> count_{0};
  std::exception_ptr error_;
};

}  // namespace sbptt::detail
