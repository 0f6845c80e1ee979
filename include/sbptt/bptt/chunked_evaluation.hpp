#pragma once
/// \file `Engine::evaluate`: the batch-mean loss of a large set without storing its trajectory.
/// The set is cut into chunks of a fixed number of samples (`evaluation_chunk_samples`, not the
/// thread count, so that the result is the same on any number of threads), each rolled out from
/// x_0 to x_m on its own (c_n = N(x_n; θ), x_{n+1} = P(x_n, c_n), engine.hpp) with buffers of its
/// own, in parallel with threads. Memory is O(B · (state_dim + network widths)) whatever the
/// horizon: each chunk keeps its buffers from call to call. Implementation detail of `Engine`.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <optional>
#include <vector>

#include "sbptt/bptt/batch_physics.hpp"
#include "sbptt/bptt/diagnostics.hpp"
#include "sbptt/bptt/engine_buffers.hpp"
#include "sbptt/bptt/objective.hpp"
#include "sbptt/core/parallel.hpp"
#include "sbptt/core/types.hpp"

namespace sbptt::detail {

/// Samples per chunk of `ChunkedEvaluation`.
inline constexpr Index evaluation_chunk_samples = 32;

/// One independently rolled-out chunk of `Engine::evaluate`: its states, controls, controller
/// workspace and the first non-finite value it met.
template <class Scalar, class Workspace, class Scratch>
struct EvaluationChunk {
  Matrix<Scalar> state, next, control;
  Workspace workspace;
  std::optional<Scratch> scratch;
  RolloutNonFinite non_finite;

  /// Rolls out `x0` (state_dim × b, samples first … first + b − 1 of the set) for `steps`
  /// steps with `controller` (packed) through `sim`, and sets `losses` (b) to each sample's
  /// loss under `objective`, `loss_steps` (b) to where each went non-finite (LossSteps).
  template <class Sim, class Controller, class Loss, class Initial, class Losses,
            class Steps>
  void roll_out(const Sim& sim, const Controller& controller, const Objective<Loss>& objective,
                Index steps, const Initial& x0, Index first, Losses&& losses,
                Steps&& loss_steps) {
    using State = typename Sim::State;
    const Index batch = x0.cols();
    const auto w = static_cast<Scalar>(objective.step_weight);
    const auto control_scale = static_cast<Scalar>(
        objective.control_weight / static_cast<double>(steps * sim.control_dim()));
    if (!scratch) scratch.emplace(sim.state_dim(), sim.control_dim());
    Scratch& t = *scratch;
    non_finite.value.reset();
    state = x0;
    non_finite.note(Quantity::State, 0, state, first);
    next.resize(sim.state_dim(), batch);
    losses.setZero();
    loss_steps.setConstant(steps);
    for (Index n = 0; n < steps; ++n) {
      controller.forward(state, control, workspace);
      non_finite.note(Quantity::Control, n, control, first);
      step_columns(sim, state, control, next, [&](auto&& body) {
        for (Index b = 0; b < batch; ++b) body(b, t);
      });
      for (Index b = 0; b < batch; ++b) {
        t.x_next = next.col(b);
        if (objective.control_weight > 0)
          losses(b) += control_scale * control.col(b).squaredNorm();
        if (objective.timing == LossTiming::Continuous || n + 1 == steps) {
          const Scalar term = w * objective.state_loss(t.x_next, static_cast<State*>(nullptr));
          losses(b) += term;
          if (loss_steps(b) == steps && !std::isfinite(term)) loss_steps(b) = n + 1;
        }
      }
      state.swap(next);
      non_finite.note(Quantity::State, n + 1, state, first);
    }
  }
};

/// The chunks of `Engine::evaluate` and the set's per-sample losses, kept from call to call so
/// that a set of the same size allocates nothing.
template <class Scalar, class Workspace, class Scratch>
class ChunkedEvaluation {
public:
  /// Batch-mean loss of rolling out `initial_states` (state_dim × B) for `steps` steps with
  /// `controller` (packed) through `sim`; sets `non_finite` to the first NaN/Inf in rollout
  /// order, or clears it. `pool` may be null (one thread).
  template <class Sim, class Controller, class Loss>
  Scalar run(const Sim& sim, const Controller& controller, const Objective<Loss>& objective,
             Index steps, const Matrix<Scalar>& initial_states, ThreadPool* pool,
             std::optional<NonFinite>& non_finite) {
    const Index batch = initial_states.cols();
    const Index count = (batch + evaluation_chunk_samples - 1) / evaluation_chunk_samples;
    if (static_cast<Index>(chunks_.size()) < count) chunks_.resize(static_cast<std::size_t>(count));
    losses_.resize(batch);
    loss_steps_.resize(batch);
    auto task = [&](Index k, Index) {
      const Index first = k * evaluation_chunk_samples;
      const Index size = std::min(evaluation_chunk_samples, batch - first);
      chunks_[static_cast<std::size_t>(k)].roll_out(sim, controller, objective, steps,
                                                    initial_states.middleCols(first, size), first,
                                                    losses_.segment(first, size),
                                                    loss_steps_.segment(first, size));
    };
    if (pool != nullptr) {
      pool->run(count, task);
    } else {
      for (Index k = 0; k < count; ++k) task(k, 0);
    }
    non_finite = first_in_rollout_order(
        count, [&](Index k) -> auto& { return chunks_[static_cast<std::size_t>(k)].non_finite; });
    return mean_of_samples(losses_, loss_steps_, non_finite);
  }

private:
  std::vector<EvaluationChunk<Scalar, Workspace, Scratch>> chunks_;
  Vector<Scalar> losses_;
  LossSteps loss_steps_;
};

}  // namespace sbptt::detail
