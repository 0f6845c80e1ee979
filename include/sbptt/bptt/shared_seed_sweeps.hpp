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
/// Threads: the sweeping thread runs both sweeps' per-sample VJPs and the one backward pass,
/// and records each step (layer adjoints and both μ_n) into a `ParamHandoff` ring with a chain
/// per sweep; each sweep's parameter products are added from it in step order, on whichever
/// thread holds that chain's lock, so the sums are the single thread's bit for bit, and the
/// two threads can add the two sweeps' products at once. The per-sample
/// loops are never split over the threads here, even where a lone sweep would split them:
/// for quantum control (2 × 8 VJPs of about 0.76 µs per step) splitting them instead of
/// handing off the products made the two-thread C epoch 301.8 ms, against 248–263 ms
/// (docs/benchmark-runs.md, fifth run).
#include <atomic>
#include <cstddef>
#include <memory>

#include "sbptt/bptt/flow_mode.hpp"
#include "sbptt/bptt/packed_controller.hpp"
#include "sbptt/bptt/param_handoff.hpp"
#include "sbptt/bptt/reverse_sweeps.hpp"
#include "sbptt/core/concepts.hpp"
#include "sbptt/core/types.hpp"
#include "sbptt/core/unroll.hpp"

namespace sbptt::detail {

/// One recorded step: the layer adjoints of the seed 1 and, per sweep (0: Full, 1:
/// PhysicsOnly), the control adjoints μ_n (1 × B) and room for the scaled adjoints. The room
/// belongs to the slot and the sweep, not to a thread, so that no call allocates after the
/// first (whichever thread adds the slot) and the two sweeps' products can run at once.
template <class Adjoints, class Scalar>
struct SharedSeedStep {
  Adjoints adjoints;
  Adjoints scaled[2];
  Matrix<Scalar> mu[2];
};

/// The shared-seed sweeps of an `Engine` (its friend) whose controller has layer adjoints of
/// type `Adjoints`.
template <class Adjoints, class Scalar>
class SharedSeedSweeps {
public:
  /// With threads, steps are handed to the engine's second thread (else added in place).
  void set_threaded(bool threaded) {
    handoff_ = threaded ? std::make_unique<Handoff>() : nullptr;
  }

  /// g_R into `result.regular`, g_M into `result.modified`, and both sweeps' diagnostics in
  /// the engine's sweep buffers, over the engine's stored trajectory.
  template <class Engine, class Pair>
  void run(Engine& engine, Pair& result, Index truncation) {
    Handoff* h = handoff_.get();
    auto add = [&](std::size_t slot, int sweep_index) {
      add_step(engine, h->ring[slot], h->steps[slot], sweep_index, result);
    };
    if (h == nullptr) {
      sweep(engine, result, truncation, nullptr, add);
    } else {
      h->run(*engine.pool_, engine.steps_, add,
             [&] { sweep(engine, result, truncation, h, add); });
    }
  }

private:
  using Step = SharedSeedStep<Adjoints, Scalar>;
  using Handoff = ParamHandoff<Step, 2>;  // a chain per sweep: g_R and g_M

  /// One machine copy (SBPTT_ONE_COPY): the calls with and without the hand-off must give the
  /// same bits, or the results would depend on the thread count.
  template <class Engine, class Pair, class Add>
  SBPTT_ONE_COPY void sweep(Engine& e, Pair& result, Index truncation, Handoff* handoff,
                            Add& add) {
    const Index batch = e.trajectory_.batch();
    auto& full = e.sweeps_[0];
    auto& physics = e.sweeps_[1];
    ReverseSweeps::begin(e, full, result.regular, handoff != nullptr);
    ReverseSweeps::begin(e, physics, result.modified, handoff != nullptr);
    unit_seed_.setOnes(1, batch);
    for (Index n = e.steps_ - 1; n >= 0; --n) {
      const auto i = static_cast<std::size_t>(n);
      const bool cut = truncated_at(n, truncation);
      ReverseSweeps::adjoint_products(e, {&full, &physics}, n, !cut, false);
      const Index k = e.steps_ - 1 - n;  // steps recorded so far
      const std::size_t slot = handoff != nullptr ? handoff->slot_for(k, add) : 0;
      Step& step = handoff != nullptr ? handoff->ring[slot] : single_;
      step.mu[0] = full.mu;
      step.mu[1] = physics.mu;
      e.packed_controller_.backward_inputs(e.trajectory_.workspaces[i], unit_seed_,
                                           cut ? nullptr : &full.input_adjoint, step.adjoints);
      if (handoff != nullptr) {
        handoff->steps[slot] = n;
        handoff->recorded.store(k + 1, std::memory_order_release);
      } else {
        add_step(e, step, n, 0, result);
        add_step(e, step, n, 1, result);
      }
      if (cut) {
        full.lambda.setZero();
        physics.lambda.setZero();
      } else {
        full.lambda.swap(full.propagated);
        full.lambda.array() += full.input_adjoint.array().rowwise() * full.mu.row(0).array();
        physics.lambda.swap(physics.propagated);
      }
    }
    if (handoff != nullptr) handoff->wait_added(e.steps_, add);
    full.end(result.regular);
    physics.end(result.modified);
  }

  /// Adds the parameter products of step `n`, recorded in `step`, of one sweep (0: Full into
  /// g_R, 1: PhysicsOnly into g_M).
  template <class Engine, class Pair>
  static void add_step(const Engine& e, Step& step, Index n, int sweep_index, Pair& result) {
    const auto& workspace = e.trajectory_.workspaces[static_cast<std::size_t>(n)];
    const auto i = static_cast<std::size_t>(sweep_index);
    e.controller_.add_param_gradient(workspace, step.adjoints, step.mu[i], step.scaled[i],
                                     sweep_index == 0 ? result.regular : result.modified);
  }

  std::unique_ptr<Handoff> handoff_;  ///< with threads
  Step single_;  ///< the one step in use without threads
  Matrix<Scalar> unit_seed_;  ///< 1 × B ones
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
