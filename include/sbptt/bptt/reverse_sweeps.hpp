#pragma once
/// \file The reverse sweeps of `Engine` over its stored trajectory: a lone sweep in any flow
/// schedule (`Engine::reverse`, and each sweep of the combined update's pair on two threads),
/// the pair step by step together on one thread, and the per-sample half of a step that every
/// sweep shares (the shared-seed sweeps of shared_seed_sweeps.hpp too). Implementation detail
/// of `Engine` (its friend).
///
/// Each sweep runs the recursion of engine.hpp's file comment from λ_m back to λ_0: the control
/// adjoint μ_n, the parameter products (∂N/∂θ)_nᵀ μ_n, then λ_n, with the propagated terms
/// dropped where the truncation window cuts (flow_mode.hpp).
#include <atomic>
#include <cstddef>
#include <cstring>
#include <initializer_list>

#include "sbptt/bptt/batch_physics.hpp"
#include "sbptt/bptt/flow_mode.hpp"
#include "sbptt/bptt/objective.hpp"
#include "sbptt/core/concepts.hpp"
#include "sbptt/core/types.hpp"

namespace sbptt::detail {

/// The sweeps of an `Engine`, as functions of it: they work in its sweep buffers, its
/// trajectory and its threads.
struct ReverseSweeps {
  /// The reverse sweep of engine.hpp's file comment into `s` and `gradient`. The loss seed of
  /// x_{n+1} is added just before the VJPs of step n (`adjoint_products`).
  /// With `handoff` the parameter products go through it (`Engine::reverse`), else they are
  /// done here.
  template <class Engine, class Sweep>
  static void lone(Engine& e, Sweep& s, const FlowSchedule& schedule,
                   Vector<typename Engine::Scalar>& gradient, Index truncation, bool parallel,
                   typename Engine::Handoff* handoff) {
    begin(e, s, gradient, handoff != nullptr);
    auto add = [&](std::size_t slot) { add_params(e, *handoff, slot, gradient); };
    for (Index n = e.steps_ - 1; n >= 0; --n) {
      const auto i = static_cast<std::size_t>(n);
      const FlowMode mode = schedule.at(n);
      const bool cut = truncated_at(n, truncation);
      const bool physics = physics_flows(mode) && !cut;
      const bool network = network_flows(mode) && !cut;
      adjoint_products(e, {&s}, n, physics, parallel);
      auto* input_adjoint = network ? &s.input_adjoint : nullptr;
      if constexpr (SplitBackwardController<typename Engine::Controller>) {
        if (handoff != nullptr) {
          const Index k = e.steps_ - 1 - n;  // recordings so far
          const std::size_t slot = handoff->slot_for(k, add);
          e.packed_controller_.backward_inputs(e.trajectory_.workspaces[i], s.mu, input_adjoint,
                                               handoff->ring[slot]);
          handoff->steps[slot] = n;
          handoff->recorded.store(k + 1, std::memory_order_release);
        }
      }
      if (handoff == nullptr) network_backward(e, s, n, gradient, input_adjoint);
      advance(s, physics, network);
    }
    if constexpr (SplitBackwardController<typename Engine::Controller>) {
      if (handoff != nullptr) handoff->wait_added(e.steps_, add);
    }
    s.end(gradient);
  }

  /// The pair's Full (g_R) and PhysicsOnly (g_M) sweeps step by step together on one thread,
  /// so that the simulator differentiates both in one call per step (`adjoint_products` of
  /// two sweeps); each sweep computes what `lone` computes alone, bit for bit.
  template <class Engine, class Pair>
  static void pair_in_step(Engine& e, Pair& result, Index truncation) {
    auto& full = e.sweeps_[0];
    auto& physics_only = e.sweeps_[1];
    begin(e, full, result.regular, false);
    begin(e, physics_only, result.modified, false);
    for (Index n = e.steps_ - 1; n >= 0; --n) {
      const bool flows = !truncated_at(n, truncation);
      adjoint_products(e, {&full, &physics_only}, n, flows, true);
      network_backward(e, full, n, result.regular, flows ? &full.input_adjoint : nullptr);
      // At the last step both sweeps start from λ_m = the loss seed, so their μ are the same
      // numbers, and so are the parameter products both gradients start with (from 0).
      if (n == e.steps_ - 1 && same_bits(physics_only.mu, full.mu)) {
        result.modified = result.regular;
      } else {
        network_backward(e, physics_only, n, result.modified, nullptr);
      }
      advance(full, flows, flows);
      advance(physics_only, flows, false);
    }
    full.end(result.regular);
    physics_only.end(result.modified);
  }

  /// The per-sample half of step n of each of `sweeps` (one, or the pair's two): λ_{n+1} += its
  /// loss seed (computed once for all), μ_n = B_nᵀλ_{n+1} (plus the control seed) and, when
  /// `physics`, A_nᵀλ_{n+1} into `s.propagated`. The loops use the first sweep's scratch. A
  /// `BatchSimulator` gets the whole batch's VJPs in one call per sweep.
  template <class Engine, class Sweep>
  static void adjoint_products(Engine& e, std::initializer_list<Sweep*> sweeps, Index n,
                               bool physics, bool parallel) {
    using Scalar = typename Engine::Scalar;
    const auto i = static_cast<std::size_t>(n);
    const auto batch = static_cast<double>(e.trajectory_.batch());
    const auto& objective = e.objective_;
    const auto seed_scale = static_cast<Scalar>(objective.step_weight / batch);  // w/B
    const auto control_seed = static_cast<Scalar>(  // 2ρ/(m·k·B)
        2.0 * objective.control_weight /
        (static_cast<double>(e.steps_ * e.sim_.control_dim()) * batch));
    const bool scored = objective.timing == LossTiming::Continuous || n + 1 == e.steps_;
    auto seed = [&](Index b, auto& t) {  // λ_{n+1} += w/B · ∂ℓ/∂x_{n+1}
      t.x = e.trajectory_.states[i + 1].col(b);
      objective.state_loss(t.x, &t.seed);
      for (Sweep* s : sweeps) s->lambda.col(b) += seed_scale * t.seed;
    };
    const auto& x = e.trajectory_.states[i];
    const auto& u = e.trajectory_.controls[i];
    detail::vjp_columns(e.sim_, x, u, sweeps, physics, scored, seed, [&](auto&& body) {
      e.fork_[1].for_samples(e.pool_.get(), e.trajectory_.batch(), (*sweeps.begin())->scratch,
                             parallel, body);
    }, e.paired_columns_);
    for (Sweep* s : sweeps) {
      s->record_adjoint(n + 1);
      if (objective.control_weight > 0) s->mu.noalias() += control_seed * u;
    }
  }

  /// λ = 0 and `gradient` = 0 (num_params) for a sweep over the stored trajectory;
  /// `overlapped`: its parameter products are added on another thread.
  template <class Engine, class Sweep>
  static void begin(const Engine& e, Sweep& s, Vector<typename Engine::Scalar>& gradient,
                    bool overlapped) {
    gradient.setZero(e.controller_.num_params());
    s.begin(e.sim_.state_dim(), e.sim_.control_dim(), e.trajectory_.batch(), e.steps_,
            overlapped);
  }

  /// Adds the parameter products recorded in `slot` of the hand-off to `gradient`.
  template <class Engine, class Handoff>
  static void add_params(const Engine& e, Handoff& h, std::size_t slot,
                         Vector<typename Engine::Scalar>& gradient) {
    if constexpr (SplitBackwardController<typename Engine::Controller>) {
      const auto step = static_cast<std::size_t>(h.steps[slot]);
      e.controller_.add_param_gradient(e.trajectory_.workspaces[step], h.ring[slot], gradient);
    }
  }

private:
  /// grad += (∂N/∂θ)_nᵀ μ_n of sweep `s` and, when `dx` is set, dx = K_nᵀ μ_n. For a
  /// `SplitBackwardController` through its two halves and the sweep's own `LayerAdjoints` (the
  /// same numbers as `backward`), so that nothing of the controller's grows per thread: the
  /// pair's sweeps run on whichever thread claims them, and a thread-local buffer would
  /// allocate the first time a sweep lands on a new thread.
  template <class Engine, class Sweep>
  static void network_backward(Engine& e, Sweep& s, Index n,
                               Vector<typename Engine::Scalar>& gradient,
                               Matrix<typename Engine::Scalar>* dx) {
    const auto& workspace = e.trajectory_.workspaces[static_cast<std::size_t>(n)];
    if constexpr (SplitBackwardController<typename Engine::Controller>) {
      auto& adjoints = e.own_adjoints(s);
      e.packed_controller_.backward_inputs(workspace, s.mu, dx, adjoints);
      e.controller_.add_param_gradient(workspace, adjoints, gradient);
    } else {
      e.packed_controller_.backward(workspace, s.mu, gradient, dx);
    }
  }

  /// Whether `a` and `b` hold the same bits (−0 and +0 differ, equal NaNs do not).
  template <class Scalar>
  static bool same_bits(const Matrix<Scalar>& a, const Matrix<Scalar>& b) {
    if (a.rows() != b.rows() || a.cols() != b.cols()) return false;
    return a.size() == 0 ||
           std::memcmp(a.data(), b.data(), sizeof(Scalar) * static_cast<std::size_t>(a.size())) ==
               0;
  }

  /// λ_n of engine.hpp's file comment from the products of step n: A_nᵀλ_{n+1} when `physics`,
  /// K_nᵀμ_n when `network`.
  template <class Sweep>
  static void advance(Sweep& s, bool physics, bool network) {
    if (physics) {
      s.lambda.swap(s.propagated);
      if (network) s.lambda += s.input_adjoint;
    } else if (network) {
      s.lambda = s.input_adjoint;
    } else {
      s.lambda.setZero();
    }
  }
};

}  // namespace sbptt::detail
