#pragma once
/// \file Both sweeps of the combined update with one backward pass of the controller per step,
/// for a controller with one output. Implementation detail of `Engine::regular_and_modified`.
///
/// Both sweeps add (∂N/∂θ)_nᵀ μ_n at every step n, each with its own control adjoint μ_n. With
/// one control, μ_n is a number per sample, and the controller's backward pass is linear in
/// each sample's seed: the layer adjoints Δ_l(μ) are Δ_l(1)·diag(μ). So one pass with the seed
/// 1 records Δ_l(1); the Full sweep scales them by its μ_n for g_R, and its input adjoint
/// K_nᵀ1 for λ_n; the PhysicsOnly sweep scales them by its own μ_n for g_M. That saves the
/// PhysicsOnly sweep's layer VJPs, about half of its network work (docs/design.md). Results
/// equal the two separate sweeps up to round-off, because (μ·Δ(1))·x is another grouping of
/// the same products.
///
/// Threads: the steps are split between the two threads, each adding the products of the
/// backward passes it mostly ran itself, so that the layer adjoints seldom leave the core
/// that wrote them (step_split.hpp). The products of the split's tasks (4 of every 7
/// recordings k = m − 1 − n, `StepShare`) are summed apart from those of the other recordings
/// and added to them at the end, on one thread as on two, so the results are the same bits for
/// every thread count. The per-sample loops are never split over the threads here, even where
/// a lone sweep would split them: for quantum control (2 × 8 VJPs of about 0.76 µs per step)
/// splitting them instead of handing the products to the second thread (the schedule before
/// this one) made the two-thread C epoch 301.8 ms, against 248–263 ms (docs/benchmark-runs.md,
/// fifth run).
#include <array>
#include <atomic>
#include <cstddef>
#include <memory>

#include "sbptt/bptt/flow_mode.hpp"
#include "sbptt/bptt/packed_controller.hpp"
#include "sbptt/bptt/reverse_sweeps.hpp"
#include "sbptt/bptt/step_split.hpp"
#include "sbptt/core/concepts.hpp"
#include "sbptt/core/types.hpp"
#include "sbptt/core/unroll.hpp"

namespace sbptt::detail {

/// The shared-seed sweeps of an `Engine` (its friend) whose controller has layer adjoints of
/// type `Adjoints`.
template <class Adjoints, class Scalar>
class SharedSeedSweeps {
public:
  /// With threads, the split's tasks go to the engine's second thread.
  void set_threaded(bool threaded) { split_ = threaded ? std::make_unique<Split>() : nullptr; }

  /// g_R into `result.regular`, g_M into `result.modified`, and both sweeps' diagnostics in
  /// the engine's sweep buffers, over the engine's stored trajectory; the split's tasks on the
  /// engine's second thread when `threaded` (and threads were set).
  template <class Engine, class Pair>
  void run(Engine& engine, Pair& result, Index truncation, bool threaded) {
    Split* split = threaded ? split_.get() : nullptr;
    unit_seed_.setOnes(1, engine.trajectory_.batch());  // before the second thread reads it
    if (split == nullptr) {
      sweep(engine, result, truncation, nullptr);
      return;
    }
    split->reset(engine.steps_);
    auto prepare = [&](Index task, Slot& slot) { prepare_task(engine, truncation, task, slot); };
    auto add = [&](Index task, Slot& slot) { add_task(engine, task, slot); };
    auto second = [&](Index, Index) { split->keep_working(prepare, add); };
    engine.pool_->run_beside(1, second, [&] {
      try {
        sweep(engine, result, truncation, split);
      } catch (...) {
        split->abandoned.store(true, std::memory_order_release);
        throw;
      }
    });
  }

private:
  using Split = StepSplit<Adjoints, Scalar>;
  using Slot = typename Split::Slot;
  using Scaled = std::array<Adjoints, 2>;
  using Seeds = std::array<Matrix<Scalar>, 2>;

  /// The pair over the whole trajectory, the tasks' work in `split` if set. One
  /// machine copy (SBPTT_ONE_COPY) with and without the split, and every backward pass and
  /// every product through one copy too (`backward_pass`, `add_products`): the two must give
  /// the same bits, or the results would depend on the thread count. Returns early, its work
  /// unfinished, when the second thread failed; `run_beside` then rethrows its exception.
  template <class Engine, class Pair>
  SBPTT_ONE_COPY void sweep(Engine& e, Pair& result, Index truncation, Split* split) {
    auto& full = e.sweeps_[0];
    auto& physics = e.sweeps_[1];
    auto prepare = [&](Index task, Slot& slot) { prepare_task(e, truncation, task, slot); };
    auto add = [&](Index task, Slot& slot) { add_task(e, task, slot); };
    ReverseSweeps::begin(e, full, result.regular, split != nullptr);
    ReverseSweeps::begin(e, physics, result.modified, split != nullptr);
    tasks_regular_.setZero(result.regular.size());
    tasks_modified_.setZero(result.modified.size());
    for (Index k = 0; k < e.steps_; ++k) {
      const Index n = e.steps_ - 1 - k;
      const bool cut = truncated_at(n, truncation);
      const bool is_task = StepShare::is_task(k);
      ReverseSweeps::adjoint_products(e, {&full, &physics}, n, !cut, false);
      const Matrix<Scalar>* input_adjoint = &full.input_adjoint;  // K_nᵀ1
      if (split != nullptr && is_task) {
        const Index task = StepShare::tasks_before(k);
        Seeds& mu = split->mu[static_cast<std::size_t>(task)];
        mu[0] = full.mu;
        mu[1] = physics.mu;
        split->swept.store(task + 1, std::memory_order_release);
        if (!split->wait_prepared(task, prepare, add)) return;
        input_adjoint = &split->input_adjoints[static_cast<std::size_t>(task)];
      } else {
        backward_pass(e, n, cut, unit_seed_, adjoints_, full.input_adjoint);
        add_products(e, n, adjoints_, full.mu, physics.mu, scaled_,
                     is_task ? tasks_regular_ : result.regular,
                     is_task ? tasks_modified_ : result.modified);
      }
      if (cut) {
        full.lambda.setZero();
        physics.lambda.setZero();
      } else {
        full.lambda.swap(full.propagated);
        full.lambda.array() += input_adjoint->array().rowwise() * full.mu.row(0).array();
        physics.lambda.swap(physics.propagated);
      }
    }
    if (split != nullptr && !split->wait_added(add)) return;
    result.regular += tasks_regular_;
    result.modified += tasks_modified_;
    full.end(result.regular);
    physics.end(result.modified);
  }

  /// Task j of the split: the backward pass of its recording.
  template <class Engine>
  void prepare_task(const Engine& e, Index truncation, Index task, Slot& slot) const {
    const Index n = step_of(e, task);
    backward_pass(e, n, truncated_at(n, truncation), unit_seed_, slot.adjoints,
                  split_->input_adjoints[static_cast<std::size_t>(task)]);
  }

  /// The products of task j into the tasks' sums.
  template <class Engine>
  void add_task(const Engine& e, Index task, Slot& slot) {
    const Seeds& mu = split_->mu[static_cast<std::size_t>(task)];
    add_products(e, step_of(e, task), slot.adjoints, mu[0], mu[1], slot.scaled,
                 tasks_regular_, tasks_modified_);
  }

  template <class Engine>
  static Index step_of(const Engine& e, Index task) {
    return e.steps_ - 1 - StepShare::recording_of(task);
  }

  /// The backward pass of step `n` with the seed 1: its layer adjoints, and K_nᵀ1 into
  /// `input_adjoint` unless the truncation window cuts there. Sized even where it cuts: a
  /// task's K_nᵀ1 is its own, and a later call without truncation must not allocate it.
  template <class Engine>
  SBPTT_ONE_COPY static void backward_pass(const Engine& e, Index n, bool cut,
                                           const Matrix<Scalar>& unit_seed, Adjoints& adjoints,
                                           Matrix<Scalar>& input_adjoint) {
    if (cut) input_adjoint.resize(e.sim_.state_dim(), e.trajectory_.batch());
    e.packed_controller_.backward_inputs(e.trajectory_.workspaces[static_cast<std::size_t>(n)],
                                         unit_seed, cut ? nullptr : &input_adjoint, adjoints);
  }

  /// Adds the parameter products of step `n` from its backward pass `adjoints`: scaled by the
  /// Full sweep's μ_n into `regular`, by the PhysicsOnly sweep's into `modified`.
  template <class Engine>
  SBPTT_ONE_COPY static void add_products(const Engine& e, Index n, const Adjoints& adjoints,
                                          const Matrix<Scalar>& mu_full,
                                          const Matrix<Scalar>& mu_physics, Scaled& scaled,
                                          Vector<Scalar>& regular, Vector<Scalar>& modified) {
    const auto& workspace = e.trajectory_.workspaces[static_cast<std::size_t>(n)];
    e.controller_.add_param_gradient(workspace, adjoints, mu_full, scaled[0], regular);
    e.controller_.add_param_gradient(workspace, adjoints, mu_physics, scaled[1], modified);
  }

  std::unique_ptr<Split> split_;  ///< with threads
  Adjoints adjoints_;             ///< the backward pass of a step run in `sweep`
  Scaled scaled_;                 ///< its seeds scaled by each sweep's μ_n
  Vector<Scalar> tasks_regular_, tasks_modified_;  ///< the tasks' sums of g_R and g_M
  Matrix<Scalar> unit_seed_;      ///< 1 × B ones
};

/// `SharedSeedSweeps` for a `SeedScalingController`, else `Absent`.
template <class C, bool = SeedScalingController<C>>
struct SharedSeedSweepsOf {
  using Type = Absent;
};
template <class C>
struct SharedSeedSweepsOf<C, true> {
  using Type = SharedSeedSweeps<typename C::LayerAdjoints, typename C::Scalar>;
};

}  // namespace sbptt::detail
