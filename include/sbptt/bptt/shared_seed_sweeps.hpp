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
#include <array>
#include <atomic>
#include <cstddef>
#include <memory>
#include <span>
#include <utility>

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
    auto add = [&](Index first, Index count, int sweep_index) {
      std::array<std::pair<Step*, Index>, Handoff::kStepsPerAdd> steps;
      for (Index j = 0; j < count; ++j) {
        const std::size_t slot = Handoff::slot(first + j);
        steps[static_cast<std::size_t>(j)] = {&h->ring[slot], h->steps[slot]};
      }
      add_steps(engine, std::span(steps.data(), static_cast<std::size_t>(count)), sweep_index,
                result);
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
      Step& step = handoff != nullptr ? handoff->ring[slot] : held_[k % 2];
      step.mu[0] = full.mu;
      step.mu[1] = physics.mu;
      e.packed_controller_.backward_inputs(e.trajectory_.workspaces[i], unit_seed_,
                                           cut ? nullptr : &full.input_adjoint, step.adjoints);
      if (handoff != nullptr) {
        handoff->steps[slot] = n;
        handoff->recorded.store(k + 1, std::memory_order_release);
      } else if (k % 2 == 1) {  // two steps held: n + 1's in held_[0], n's in held_[1]
        add_held(e, 2, n, result);
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
    if (handoff != nullptr) {
      handoff->wait_added(e.steps_, add);
    } else if (e.steps_ % 2 == 1) {  // the last step (n = 0) alone
      add_held(e, 1, 0, result);
    }
    full.end(result.regular);
    physics.end(result.modified);
  }

  /// Adds the parameter products of `steps` (each a recording and its time step), in their
  /// order, of one sweep (0: Full into g_R, 1: PhysicsOnly into g_M).
  template <class Engine, class Pair>
  static void add_steps(const Engine& e, std::span<const std::pair<Step*, Index>> steps,
                        int sweep_index, Pair& result) {
    using Controller = typename Engine::Controller;
    const auto i = static_cast<std::size_t>(sweep_index);
    std::array<StepProducts<Controller>, 2> products;
    for (std::size_t k = 0; k < steps.size(); ++k) {
      Step& step = *steps[k].first;
      products[k] = {&e.trajectory_.workspaces[static_cast<std::size_t>(steps[k].second)],
                     &step.adjoints, &step.mu[i], &step.scaled[i]};
    }
    add_step_products(e.controller_,
                      std::span<const StepProducts<Controller>>(products.data(), steps.size()),
                      sweep_index == 0 ? result.regular : result.modified);
  }

  /// Without threads: adds both sweeps' products of the `count` steps held, the last of them
  /// step `n` (held_[0] holds step n + count − 1).
  template <class Engine, class Pair>
  void add_held(const Engine& e, Index count, Index n, Pair& result) {
    const std::array<std::pair<Step*, Index>, 2> steps{std::pair{&held_[0], n + count - 1},
                                                       std::pair{&held_[1], n}};
    for (int sweep_index : {0, 1})
      add_steps(e, std::span(steps.data(), static_cast<std::size_t>(count)), sweep_index,
                result);
  }

  std::unique_ptr<Handoff> handoff_;  ///< with threads
  Step held_[2];  ///< without threads: recordings 2j and 2j + 1, added together
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
