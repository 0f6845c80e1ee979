#pragma once
/// \file The hand-off of a reverse sweep's parameter products to a second thread, in an order
/// that keeps every sum the single thread's. Implementation detail of `sbptt::Engine`.
#include <algorithm>
#include <array>
#include <atomic>
#include <cstddef>
#include <mutex>
#include <thread>
#include <vector>

#include "sbptt/bptt/packed_controller.hpp"
#include "sbptt/core/concepts.hpp"
#include "sbptt/core/parallel.hpp"
#include "sbptt/core/types.hpp"

namespace sbptt::detail {

/// The hand-off of parameter products to a second thread. The sweeping thread records each
/// step into a ring slot and counts it in `recorded`. A slot's products form `Chains`
/// independent chains, each summed into a gradient of its own (a lone sweep: one; the pair of
/// the combined update: two, g_R and g_M). Whoever holds a chain's lock adds that chain's
/// recorded slots in recording order and counts them in the chain's `added`: the other thread
/// while it keeps up, the sweeping thread when it must wait for a slot (then only up to that
/// slot, so that it soon goes back to sweeping) and at the end. So each gradient is summed in
/// one fixed order, the same as on one thread, and with two chains both threads can add at
/// once. The sweep never waits for a thread that may not have started (the adder runs beside
/// it, `ThreadPool::run_beside`, and stops once every slot is added or the sweep has thrown).
/// Nobody sleeps on a lock (`try_lock`, then `pause`, and `yield` once a wait has lasted 2048
/// turns): a step takes a few microseconds, less than waking a sleeping thread.
template <class Adjoints, int Chains = 1>
struct ParamHandoff {
  static constexpr Index ring_size = 16;
  struct Chain {
    std::atomic<Index> added{0};
    std::mutex lock;
  };
  std::vector<Adjoints> ring = std::vector<Adjoints>(ring_size);
  std::vector<Index> steps = std::vector<Index>(ring_size);  ///< time step of each slot
  std::atomic<Index> recorded{0};
  std::array<Chain, Chains> chains;
  std::atomic<bool> abandoned{false};  ///< the sweep threw: the adder stops

  void reset() {
    recorded.store(0, std::memory_order_relaxed);
    for (Chain& chain : chains) chain.added.store(0, std::memory_order_relaxed);
    abandoned.store(false, std::memory_order_relaxed);
  }

  /// Recordings added in every chain.
  [[nodiscard]] Index added() const {
    Index fewest = chains[0].added.load(std::memory_order_acquire);
    for (const Chain& chain : chains)
      fewest = std::min(fewest, chain.added.load(std::memory_order_acquire));
    return fewest;
  }

  /// Adds chain `c` of the recordings before number `until` not yet added, if its lock is
  /// free; `add(slot, c)` adds one. False if another thread held the lock.
  template <class Add>
  bool try_adding(Add& add, int c, Index until) {
    Chain& chain = chains[static_cast<std::size_t>(c)];
    const std::unique_lock<std::mutex> guard(chain.lock, std::try_to_lock);
    if (!guard.owns_lock()) return false;
    const Index last = std::min(until, recorded.load(std::memory_order_acquire));
    for (Index k = chain.added.load(std::memory_order_relaxed); k < last; ++k) {
      add(static_cast<std::size_t>(k % ring_size), c);
      chain.added.store(k + 1, std::memory_order_release);
    }
    return true;
  }

  /// One turn of a wait: `pause` at first, then yield the core, because on a machine with
  /// fewer free cores than threads the thread waited for may have been preempted.
  static void back_off(int& turns) {
    if (++turns < 2048) {
      cpu_relax();
    } else {
      std::this_thread::yield();
    }
  }

  /// Returns once at least `count` recordings are added in every chain, adding them itself
  /// when it can.
  template <class Add>
  void wait_added(Index count, Add& add) {
    int turns = 0;
    while (added() < count) {
      for (int c = 0; c < Chains; ++c)
        if (chains[static_cast<std::size_t>(c)].added.load(std::memory_order_acquire) < count)
          try_adding(add, c, count);
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
  /// in every chain (or the sweep gave up).
  template <class Add>
  void keep_adding(Index total, Add& add) {
    int turns = 0;
    while (!abandoned.load(std::memory_order_acquire)) {
      if (added() == total) return;
      const Index available = recorded.load(std::memory_order_acquire);
      bool progressed = false;
      for (int c = 0; c < Chains; ++c)
        if (available > chains[static_cast<std::size_t>(c)].added.load(std::memory_order_acquire))
          progressed = try_adding(add, c, available) || progressed;
      if (progressed) {
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
