#pragma once
/// \file The engine's reusable buffers (per thread, per sweep) and its scan for the first
/// non-finite value. Implementation details of `sbptt::Engine`.
#include <cmath>
#include <optional>
#include <vector>

#include "sbptt/bptt/diagnostics.hpp"
#include "sbptt/core/non_finite.hpp"
#include "sbptt/core/types.hpp"

namespace sbptt::detail {

/// Sets `slot` to the first non-finite entry of `values` (scanning sample by sample), with
/// samples numbered from `first`; leaves it alone when every entry is finite.
template <class Derived>
void note_first_non_finite(Quantity quantity, Index step, const Eigen::DenseBase<Derived>& values,
                           std::optional<NonFinite>& slot, Index first = 0) {
  if (const auto at = first_non_finite(values))
    slot = NonFinite{quantity, step, first + at->column,
                     static_cast<double>(values(at->row, at->column))};
}

/// The first non-finite value that a rollout of some of a batch's samples met, with its place
/// in rollout order (by step, the control c_n before the state x_{n+1}, then by sample), so
/// that parts of a batch rolled out apart report what one rollout of the whole batch would.
struct RolloutNonFinite {
  std::optional<NonFinite> value;
  Index order = 0;  ///< 2n for the control c_n, 2n − 1 for the state x_n

  /// Notes the first non-finite entry of `values` (samples numbered from `first`) unless one
  /// is already noted.
  template <class Values>
  void note(Quantity quantity, Index step, const Values& values, Index first) {
    if (value) return;
    note_first_non_finite(quantity, step, values, value, first);
    if (value) order = quantity == Quantity::Control ? 2 * step : 2 * step - 1;
  }
};

/// The first of `count` parts' values in rollout order, `part(k)` giving part k's
/// `RolloutNonFinite`; parts cover the samples in order, so at one place the earlier part's
/// value comes first.
template <class Part>
[[nodiscard]] std::optional<NonFinite> first_in_rollout_order(Index count, Part&& part) {
  const RolloutNonFinite* first = nullptr;
  for (Index k = 0; k < count; ++k) {
    const RolloutNonFinite& p = part(k);
    if (p.value && (first == nullptr || p.order < first->order)) first = &p;
  }
  return first != nullptr ? first->value : std::nullopt;
}

/// The first non-finite component of a gradient or parameter vector, reported as `quantity`
/// (step −1, `sample` = parameter index).
template <class Scalar>
[[nodiscard]] std::optional<NonFinite> first_non_finite_component(const Vector<Scalar>& g,
                                                                  Quantity quantity) {
  if (const auto at = first_non_finite(g))
    return NonFinite{quantity, -1, at->row, static_cast<double>(g(at->row))};
  return std::nullopt;
}

/// Buffers and report of one reverse sweep: λ, A_nᵀλ, μ and K_nᵀμ (state_dim or control_dim
/// × B), plus one scratch per thread. Two of them let both sweeps of the combined update run at
/// the same time.
template <class Scalar, class Scratch>
struct SweepBuffers {
  Matrix<Scalar> lambda, propagated, mu, input_adjoint;
  SweepDiagnostics diagnostics;
  std::vector<Scratch> scratch;

  /// λ = 0 and the report cleared, for a sweep of `steps` steps over `batch` samples.
  void begin(Index state_dim, Index control_dim, Index batch, Index steps, bool overlapped) {
    lambda.setZero(state_dim, batch);
    mu.resize(control_dim, batch);
    propagated.resize(state_dim, batch);
    diagnostics.adjoint_norms.assign(static_cast<std::size_t>(steps + 1), 0.0);
    diagnostics.first_non_finite.reset();
    diagnostics.params_overlapped = overlapped;
  }

  /// Reports ‖λ‖ as λ_n, and its first non-finite entry unless one is already reported (a
  /// scan only when ‖λ‖² is not finite).
  void record_adjoint(Index n) {
    const Scalar squares = lambda.squaredNorm();
    diagnostics.adjoint_norms[static_cast<std::size_t>(n)] =
        static_cast<double>(std::sqrt(squares));
    if (!diagnostics.first_non_finite && !squares_show_all_finite(squares))
      note_first_non_finite(Quantity::Adjoint, n, lambda, diagnostics.first_non_finite);
  }

  /// Records λ_0 and reports the finished `gradient` (likewise).
  void end(const Vector<Scalar>& gradient) {
    record_adjoint(0);
    const Scalar squares = gradient.squaredNorm();
    diagnostics.grad_norm2 = static_cast<double>(squares);
    if (!diagnostics.first_non_finite && !squares_show_all_finite(squares))
      diagnostics.first_non_finite = first_non_finite_component(gradient, Quantity::Gradient);
  }
};

/// Per sample, the step n of the first state loss ℓ(x_n) that is not finite; the last step
/// where every term is finite (a sum or a control term that overflowed, or no overflow).
using LossSteps = Eigen::Matrix<Index, Eigen::Dynamic, 1>;

/// Mean of per-sample losses, summed in sample order (thread-count independent); notes the
/// first non-finite one in `slot` (at its step in `steps`) unless `slot` already holds a value.
template <class Scalar>
[[nodiscard]] Scalar mean_of_samples(const Vector<Scalar>& losses, const LossSteps& steps,
                                     std::optional<NonFinite>& slot) {
  Scalar total = 0;
  for (Index b = 0; b < losses.size(); ++b) {
    if (!slot && !std::isfinite(losses(b)))
      slot = NonFinite{Quantity::Loss, steps(b), b, static_cast<double>(losses(b))};
    total += losses(b);
  }
  return total / static_cast<Scalar>(losses.size());
}

}  // namespace sbptt::detail
