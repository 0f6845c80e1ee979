#pragma once
/// \file The hand-off of a reverse sweep's parameter products to a second thread, in an order
/// that keeps every sum the single thread's. Implementation detail of `sbptt::Engine`.
#include <algorithm>
#include <atomic>
#include <cstddef>
#include <mutex>
#include <vector>

#include "sbptt/bptt/packed_controller.hpp"
#include "sbptt/core/concepts.hpp"
#include "sbptt/core/parallel.hpp"
#include "sbptt/core/types.hpp"

namespace sbptt::detail {

/// The hand-off of a lone sweep's parameter products to a second thread. The sweeping thread
/// records each step into a ring slot and counts it in `recorded`. Whoever holds the lock adds
/// the recorded slots in recording order and counts them in `added`: the other thread while it
/// keeps up, the sweeping thread when it must wait for a slot (then only up to that slot, so
/// that it soon goes back to sweeping) and at the end. So the gradient is summed in one fixed
/// order, the same as on one thread. The sweep never waits for a thread that may not have
/// started (the adder runs beside it, `ThreadPool::run_beside`, and stops once every slot is
/// added or the sweep has thrown). Nobody sleeps on the lock (`try_lock`, then `back_off`).
template <class Adjoints>
struct ParamHandoff {
  static constexpr Index ring_size = 16;
  std::vector<Adjoints> ring = std::vector<Adjoints>(ring_size);
  std::vector<Index> steps = std::vector<Index>(ring_size);  ///< time step of each slot
  std::atomic<Index> recorded{0};
  std::atomic<Index> added{0};
  std::mutex lock;
  std::atomic<bool> abandoned{false};  ///< the sweep threw: the adder stops

  void reset() {
    recorded.store(0, std::memory_order_relaxed);
    added.store(0, std::memory_order_relaxed);
    abandoned.store(false, std::memory_order_relaxed);
  }

  /// Adds the recordings before number `until` not yet added, if the lock is free; `add(slot)`
  /// adds one. False if another thread held the lock.
  template <class Add>
  bool try_adding(Add& add, Index until) {
    const std::unique_lock<std::mutex> guard(lock, std::try_to_lock);
    if (!guard.owns_lock()) return false;
    const Index last = std::min(until, recorded.load(std::memory_order_acquire));
    for (Index k = added.load(std::memory_order_relaxed); k < last; ++k) {
      add(static_cast<std::size_t>(k % ring_size));
      added.store(k + 1, std::memory_order_release);
    }
    return true;
  }

  /// Returns once at least `count` recordings are added, adding them itself when it can.
  template <class Add>
  void wait_added(Index count, Add& add) {
    int turns = 0;
    while (added.load(std::memory_order_acquire) < count) {
      try_adding(add, count);
      back_off(turns);
    }
  }

  /// The slot for recording number `k`, once its previous content has been added.
  template <class Add>
  [[nodiscard]] std::size_t slot_for(Index k, Add& add) {
    wait_added(k - ring_size + 1, add);
    return static_cast<std::size_t>(k % ring_size);
  }

  /// Runs `sweep` on this thread while a second thread of `pool` adds the `total` slots it
  /// records with `add`.
  template <class Add, class Sweep>
  void run(ThreadPool& pool, Index total, Add& add, Sweep&& sweep) {
    reset();
    auto adder = [&](Index, Index) { keep_adding(total, add); };
    pool.run_beside(1, adder, [&] {
      try {
        sweep();
      } catch (...) {
        abandoned.store(true, std::memory_order_release);
        throw;
      }
    });
  }

  /// The second thread's part: adds slots as they are recorded until all `total` are added
  /// (or the sweep gave up).
  template <class Add>
  void keep_adding(Index total, Add& add) {
    int turns = 0;
    while (!abandoned.load(std::memory_order_acquire)) {
      const Index done = added.load(std::memory_order_acquire);
      if (done == total) return;
      const Index available = recorded.load(std::memory_order_acquire);
      if (available > done && try_adding(add, available)) {
        turns = 0;
      } else {
        back_off(turns);
      }
    }
  }
};

/// `ParamHandoff` of `C::LayerAdjoints` for a `SplitBackwardController`, else `Absent`.
template <class C, bool = SplitBackwardController<C>>
struct ParamHandoffOf {
  using Type = Absent;
};
template <class C>
struct ParamHandoffOf<C, true> {
  using Type = ParamHandoff<typename C::LayerAdjoints>;
};

}  // namespace sbptt::detail
