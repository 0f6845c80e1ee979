#pragma once
/// \file The steps of the combined update's shared-seed pair split between two threads, each
/// thread adding the parameter products of the backward passes it mostly ran itself.
/// Implementation detail of `SharedSeedSweeps` (shared_seed_sweeps.hpp).
///
/// The pair records its steps from the last: recording k is step n = m − 1 − k. The sweeping
/// thread runs the VJPs of every step; the network's work of each step (its backward pass and
/// parameter products) goes to one thread or the other, by a fixed pattern (`StepShare`): 4 of
/// every 7 recordings are the tasks of this split, the rest the sweep's own. A task's backward
/// pass (the seed 1: Δ_l(1) and K_nᵀ1) reads only the forward pass, so the second thread runs
/// it ahead of the sweep, into a ring slot; its products need both sweeps' μ_n, which the sweep
/// records here when it reaches the step. So in the steady state Δ (6.4 KB a step for the cart
/// pole) is written and read on one core, and only K_nᵀ1 and the μ_n cross
/// (docs/benchmark-runs-zen4.md, thirty-sixth run).
/// The tasks' products are added in task order under a lock, into sums of their own.
///
/// The sweep never waits for a thread that may not have started: until the second thread has
/// started, the sweep runs the tasks it needs itself, and it adds products while it waits; so
/// it finishes even if the second thread never starts. Once that thread runs, the sweep leaves
/// it the products, except at the end, where it helps add what is left. While it waits for a
/// backward pass, it runs the next one that no thread has begun (the second thread may be
/// busy adding products, as quantum control's often is): that task's Δ then crosses to the
/// other core, but the sweep does not idle. The cart pole's second thread is ahead, and its
/// batches took as long either way; quantum's took 0.4–2.9% less (docs/design.md, decision of
/// 2026-12-05). If the second thread throws, it says so (`failed`), and the sweep stops
/// waiting and returns, so that `ThreadPool::run_beside` rethrows that thread's exception.
#include <array>
#include <atomic>
#include <cstddef>
#include <mutex>
#include <vector>

#include "sbptt/core/parallel.hpp"
#include "sbptt/core/types.hpp"

namespace sbptt::detail {

/// Which recordings are the split's tasks: 4 of every 7, spread evenly (1, 3, 5, 6, 8, 10, 12,
/// 13, …). Fixed, not measured at run time, so that the sums are grouped alike for every
/// machine and thread count. More than half, because the sweeping thread also runs every
/// step's VJPs: the cart pole's second thread, at 7 of 13, still waited for the sweep; where
/// the second thread is the busier one (quantum control), the sweep runs backward passes while
/// it waits (`wait_prepared`), so the larger share does not make it idle (docs/design.md,
/// decisions of 2026-11-30 and 2026-12-05).
struct StepShare {
  static constexpr Index tasks_per_period = 4, period = 7;

  [[nodiscard]] static constexpr bool is_task(Index recording) {
    return tasks_before(recording + 1) > tasks_before(recording);
  }
  /// The tasks among recordings 0 … recordings − 1; for a task, its number.
  [[nodiscard]] static constexpr Index tasks_before(Index recordings) {
    return recordings * tasks_per_period / period;
  }
  /// The recording of task j: the least k with tasks_before(k + 1) = j + 1.
  [[nodiscard]] static constexpr Index recording_of(Index task) {
    return ((task + 1) * period + tasks_per_period - 1) / tasks_per_period - 1;
  }
};

/// The shared state of a `SharedSeedSweeps` call on two threads. `Adjoints` are a controller's
/// layer adjoints.
template <class Adjoints, class Scalar>
struct StepSplit {
  static constexpr Index ring_size = 8;
  /// A task's backward pass, and room for its seeds scaled by each sweep's μ_n (the room
  /// belongs to the slot, not to a thread, so that no call allocates after the first).
  struct Slot {
    Adjoints adjoints;
    std::array<Adjoints, 2> scaled;
  };
  std::array<Slot, ring_size> slots;
  /// Per slot, the number + 1 of the last task whose backward pass is in it (`is_prepared`).
  alignas(64) std::array<std::atomic<Index>, ring_size> prepared{};
  std::vector<Matrix<Scalar>> input_adjoints;        ///< K_nᵀ1 of each task
  std::vector<std::array<Matrix<Scalar>, 2>> mu;     ///< both sweeps' μ_n of each task
  Index tasks = 0;
  alignas(64) std::atomic<Index> swept{0};    ///< tasks whose μ_n are recorded
  alignas(64) std::atomic<Index> claimed{0};  ///< tasks whose backward pass someone has begun
  alignas(64) std::atomic<Index> added{0};    ///< tasks whose products are added
  std::atomic<bool> started{false};           ///< the second thread has begun
  std::atomic<bool> abandoned{false};         ///< the sweep threw: the second thread stops
  std::atomic<bool> failed{false};            ///< the second thread threw: the sweep returns
  std::mutex add_lock;

  /// Ready for a sweep of `steps` steps.
  void reset(Index steps) {
    tasks = StepShare::tasks_before(steps);
    if (static_cast<Index>(mu.size()) < tasks) {
      input_adjoints.resize(static_cast<std::size_t>(tasks));
      mu.resize(static_cast<std::size_t>(tasks));
    }
    for (std::atomic<Index>& flag : prepared) flag.store(0, std::memory_order_relaxed);
    swept.store(0, std::memory_order_relaxed);
    claimed.store(0, std::memory_order_relaxed);
    added.store(0, std::memory_order_relaxed);
    started.store(false, std::memory_order_relaxed);
    abandoned.store(false, std::memory_order_relaxed);
    failed.store(false, std::memory_order_relaxed);
  }

  Slot& slot_of(Index task) { return slots[static_cast<std::size_t>(task % ring_size)]; }
  std::atomic<Index>& prepared_of(Index task) {
    return prepared[static_cast<std::size_t>(task % ring_size)];
  }

  /// Whether the backward pass of `task` is done. Its slot may already hold a later task's:
  /// once a task is added, its slot is free, and the sweep may look only after that.
  [[nodiscard]] bool is_prepared(Index task) {
    return prepared_of(task).load(std::memory_order_acquire) > task;
  }

  /// Claims the next task and runs `prepare(task, slot)`, if there is one and its slot is
  /// free; false otherwise, or if the other thread claimed it first.
  template <class Prepare>
  bool try_preparing(Prepare& prepare) {
    Index task = claimed.load(std::memory_order_acquire);
    if (task >= tasks || task - added.load(std::memory_order_acquire) >= ring_size) return false;
    if (!claimed.compare_exchange_strong(task, task + 1, std::memory_order_acq_rel)) return false;
    prepare(task, slot_of(task));
    prepared_of(task).store(task + 1, std::memory_order_release);
    return true;
  }

  /// Adds, with `add(task, slot)`, the next task in order if it is prepared and swept and the
  /// lock is free; true if it did. One at a time, so that the second thread looks again
  /// whether the sweep will soon need a backward pass before it adds another.
  template <class Add>
  bool try_adding(Add& add) {
    const std::unique_lock<std::mutex> guard(add_lock, std::try_to_lock);
    if (!guard.owns_lock()) return false;
    const Index task = added.load(std::memory_order_relaxed);
    if (task >= tasks || swept.load(std::memory_order_acquire) <= task || !is_prepared(task))
      return false;
    add(task, slot_of(task));
    added.store(task + 1, std::memory_order_release);
    return true;
  }

  /// The sweep's wait for the backward pass of `task`: meanwhile it runs the next backward pass
  /// that no thread has begun (this task's, or a later one's while the second thread runs this
  /// one), and adds products too while the second thread has not started; false if the second
  /// thread failed.
  template <class Prepare, class Add>
  bool wait_prepared(Index task, Prepare& prepare, Add& add) {
    int turns = 0;
    while (!is_prepared(task)) {
      if (failed.load(std::memory_order_acquire)) return false;
      const bool alone = !started.load(std::memory_order_acquire);
      if (!(try_preparing(prepare) || (alone && try_adding(add)))) back_off(turns);
    }
    return true;
  }

  /// The sweep's wait, at its end, for every task's products, adding them too; false if the
  /// second thread failed.
  template <class Add>
  bool wait_added(Add& add) {
    int turns = 0;
    while (added.load(std::memory_order_acquire) < tasks) {
      if (failed.load(std::memory_order_acquire)) return false;
      if (!try_adding(add)) back_off(turns);  // every task is prepared by now
    }
    return true;
  }

  /// The second thread's part: backward passes ahead of the sweep (at least two prepared
  /// beyond those added), else products, until every task is added or the sweep gave up.
  template <class Prepare, class Add>
  void keep_working(Prepare& prepare, Add& add) {
    started.store(true, std::memory_order_release);
    try {
      int turns = 0;
      while (!abandoned.load(std::memory_order_acquire) &&
             added.load(std::memory_order_acquire) < tasks) {
        const bool behind =
            claimed.load(std::memory_order_acquire) < added.load(std::memory_order_acquire) + 2;
        const bool progressed = (behind && try_preparing(prepare)) || try_adding(add) ||
                                try_preparing(prepare);
        if (progressed) {
          turns = 0;
        } else {
          back_off(turns);
        }
      }
    } catch (...) {
      failed.store(true, std::memory_order_release);
      throw;
    }
  }
};

}  // namespace sbptt::detail
