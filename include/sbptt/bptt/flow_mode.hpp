#pragma once
/// \file Gradient-flow modes of the reverse sweep, and per-step schedules of them.
///
/// With A_n = ∂P/∂x, B_n = ∂P/∂c, K_n = ∂N/∂x at step n, the reverse sweep is
///
///     μ_n  = B_nᵀ λ_{n+1} + ∂r/∂c_n
///     g   += (∂N/∂θ)_nᵀ μ_n
///     λ_n  = ∂ℓ_n/∂x_n + [physics] A_nᵀ λ_{n+1} + [network] K_nᵀ μ_n
///
/// and the mode of step n switches the two bracketed paths.
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "sbptt/core/error.hpp"
#include "sbptt/core/types.hpp"

namespace sbptt {

/// Which backward paths through x_n are kept (paper labels in brackets).
enum class FlowMode {
  Full,         ///< (R) physics and network paths: the true gradient
  PhysicsOnly,  ///< (M) gradient stopped at the network input
  NetworkOnly,  ///< (N) only the path through the network input; not in the paper's plots
  Stopped,      ///< (S) neither: every control sees only the loss of the next state
};

/// True when A_nᵀ λ_{n+1} flows into λ_n.
[[nodiscard]] constexpr bool physics_flows(FlowMode mode) {
  return mode == FlowMode::Full || mode == FlowMode::PhysicsOnly;
}

/// True when K_nᵀ μ_n flows into λ_n (this is the only use of the network's input Jacobian).
[[nodiscard]] constexpr bool network_flows(FlowMode mode) {
  return mode == FlowMode::Full || mode == FlowMode::NetworkOnly;
}

/// True when a truncation window of `truncation` steps (0: none) cuts the gradient at x_n:
/// n is a positive multiple of the window, so nothing propagates from λ_{n+1} into λ_n.
[[nodiscard]] constexpr bool truncated_at(Index n, Index truncation) {
  return truncation > 0 && n > 0 && n % truncation == 0;
}

/// The paper's one-letter label: R, M, N or S.
[[nodiscard]] constexpr std::string_view label(FlowMode mode) {
  switch (mode) {
    case FlowMode::Full: return "R";
    case FlowMode::PhysicsOnly: return "M";
    case FlowMode::NetworkOnly: return "N";
    case FlowMode::Stopped: return "S";
  }
  return "?";
}

/// The mode of every step of a reverse sweep: one mode for all steps (the common case), or one
/// per step.
class FlowSchedule {
public:
  /// The same mode at every step.
  FlowSchedule(FlowMode mode) : uniform_(mode) {}  // NOLINT(google-explicit-constructor)

  /// modes[n] is the mode of step n; its size must equal the horizon of the sweep.
  explicit FlowSchedule(std::vector<FlowMode> modes)
      : uniform_(FlowMode::Full), per_step_(std::move(modes)) {
    detail::require(!per_step_.empty(), "FlowSchedule: empty per-step schedule; expected one "
                                        "mode per step");
  }

  [[nodiscard]] FlowMode at(Index step) const {
    return per_step_.empty() ? uniform_ : per_step_[static_cast<std::size_t>(step)];
  }

  /// Throws unless the schedule can drive a sweep of `steps` steps.
  void validate(Index steps) const {
    detail::require(per_step_.empty() || static_cast<Index>(per_step_.size()) == steps,
                    "FlowSchedule: ", per_step_.size(), " per-step modes for a horizon of ",
                    steps, " steps; expected exactly one mode per step");
  }

private:
  FlowMode uniform_;
  std::vector<FlowMode> per_step_;
};

}  // namespace sbptt
