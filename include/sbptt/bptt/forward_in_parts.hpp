#pragma once
/// \file The forward pass of `Engine::forward` on several threads, for a `ColumnSplitController`:
/// the batch's columns cut into one range per thread, each range rolled out from x_0 to x_m on
/// its own thread (c_n = N(x_n; θ), x_{n+1} = P(x_n, c_n), engine.hpp), with one fork per
/// rollout. The steps of a rollout wait on each other, its samples do not: a sample's numbers
/// do not depend on the samples beside it (the controller's `forward_columns`, a
/// `BatchSimulator`'s columns), so the trajectory is the one-thread trajectory bit for bit.
/// Implementation detail of `Engine` (its friend).
#include <cstddef>
#include <vector>

#include "sbptt/bptt/batch_physics.hpp"
#include "sbptt/bptt/diagnostics.hpp"
#include "sbptt/bptt/engine_buffers.hpp"
#include "sbptt/core/types.hpp"

namespace sbptt::detail {

/// One thread's samples of `Engine::forward` done in parts: their states x_0 … x_m and
/// controls c_0 … c_{m−1}, and the first non-finite value the part met.
template <class Scalar>
struct ForwardPart {
  std::vector<Matrix<Scalar>> states, controls;
  RolloutNonFinite non_finite;

  /// Sizes the buffers for `steps` steps of `count` samples (allocates only when they change).
  void resize(Index steps, Index state_dim, Index control_dim, Index count) {
    states.resize(static_cast<std::size_t>(steps) + 1);
    controls.resize(static_cast<std::size_t>(steps));
    for (auto& x : states) x.resize(state_dim, count);
    for (auto& c : controls) c.resize(control_dim, count);
  }
};

/// The parts' own states, controls and non-finite notes, one set per thread.
template <class Scalar>
class ForwardInParts {
public:
  /// Room for `slots` parts (the engine's thread count).
  void resize(std::size_t slots) { parts_.resize(slots); }

  /// The rollout of `e.forward` into `e`'s trajectory, its batch cut into `parts` ranges of
  /// columns (at most one per slot).
  template <class Engine>
  void run(Engine& e, Index parts) {
    const Index batch = e.trajectory_.batch();
    for (auto& ws : e.trajectory_.workspaces) e.packed_controller_.size_forward(batch, ws);
    auto first_of = [&](Index k) { return k * batch / parts; };
    auto roll_out_part = [&](Index k, Index slot) {
      const Index first = first_of(k), count = first_of(k + 1) - first;
      ForwardPart<Scalar>& part = parts_[static_cast<std::size_t>(k)];
      auto& scratch = e.forward_scratch_[static_cast<std::size_t>(slot)];
      part.resize(e.steps_, e.sim_.state_dim(), e.sim_.control_dim(), count);
      part.non_finite.value.reset();
      part.states[0] = e.trajectory_.states[0].middleCols(first, count);
      part.non_finite.note(Quantity::State, 0, part.states[0], first);
      for (Index n = 0; n < e.steps_; ++n) {
        const auto i = static_cast<std::size_t>(n);
        Matrix<Scalar>& x = part.states[i];
        e.packed_controller_.forward_columns(x, first, part.controls[i],
                                             e.trajectory_.workspaces[i]);
        part.non_finite.note(Quantity::Control, n, part.controls[i], first);
        step_columns(e.sim_, x, part.controls[i], part.states[i + 1], [&](auto&& body) {
          for (Index b = 0; b < count; ++b) body(b, scratch);
        });
        part.non_finite.note(Quantity::State, n + 1, part.states[i + 1], first);
      }
    };
    e.pool_->run(parts, roll_out_part);
    // Into the trajectory here, on one thread: a part writing its own columns there would
    // share the cache lines at its edges with the next part's thread at every step. The parts'
    // copies are (m + 1)·state_dim·B + m·control_dim·B numbers (35 KiB for the paper's cart
    // pole, beside its 694 KiB trajectory). The controller's workspace is still written in
    // place, so its matrices whose columns are not whole cache lines (the cart pole's input,
    // 10 floats, and output) share a line at the cut: docs/benchmark-runs.md, eleventh run.
    for (Index k = 0; k < parts; ++k) {
      const ForwardPart<Scalar>& part = parts_[static_cast<std::size_t>(k)];
      const Index first = first_of(k), count = first_of(k + 1) - first;
      for (std::size_t i = 0; i < part.controls.size(); ++i) {
        e.trajectory_.controls[i].middleCols(first, count) = part.controls[i];
        e.trajectory_.states[i + 1].middleCols(first, count) = part.states[i + 1];
      }
    }
    e.forward_non_finite_ = first_in_rollout_order(parts, [&](Index k) -> auto& {
      return parts_[static_cast<std::size_t>(k)].non_finite;
    });
  }

private:
  std::vector<ForwardPart<Scalar>> parts_;
};

}  // namespace sbptt::detail
