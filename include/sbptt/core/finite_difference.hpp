#pragma once
/// \file Central finite differences, and the public checker users run on their own
/// simulators: the finite-difference twin of every analytic derivative (controllers:
/// controller_check.hpp).
///
/// Step: h_i = ∛ε · max(1, |x_i|), which balances truncation O(h²) against round-off O(ε/h).
/// Errors are relative to the largest entry of the finite-difference reference (floored at
/// √ε so that an all-zero derivative is compared absolutely).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <initializer_list>
#include <limits>
#include <string>

#include "sbptt/core/concepts.hpp"
#include "sbptt/core/simulator_output.hpp"

namespace sbptt {

/// Default central-difference step scale ∛ε for `Scalar`.
template <class Scalar>
[[nodiscard]] Scalar default_fd_step() {
  return std::cbrt(std::numeric_limits<Scalar>::epsilon());
}

/// Central difference Jacobian of `f: R^n → R^m` at `x`, where `f(x, out)` writes out (size m).
/// Returns the m × n matrix.
template <class Scalar, class Function>
[[nodiscard]] Matrix<Scalar> finite_difference_jacobian(Function&& f, Vector<Scalar> x, Index m,
                                                        Scalar step = default_fd_step<Scalar>()) {
  Matrix<Scalar> jac(m, x.size());
  Vector<Scalar> plus(m), minus(m);
  for (Index i = 0; i < x.size(); ++i) {
    const Scalar xi = x(i);
    const Scalar h = step * std::max(Scalar(1), std::abs(xi));
    x(i) = xi + h;
    f(x, plus);
    x(i) = xi - h;
    f(x, minus);
    x(i) = xi;
    jac.col(i) = (plus - minus) / (Scalar(2) * h);
  }
  return jac;
}

/// max |analytic − reference| / max(max |reference|, √ε); NaN if either holds a NaN (Eigen's
/// default maxCoeff may skip one), infinity if their shapes differ (a product never written).
template <class Scalar>
[[nodiscard]] Scalar relative_error(const Matrix<Scalar>& analytic, const Matrix<Scalar>& reference) {
  if (analytic.rows() != reference.rows() || analytic.cols() != reference.cols())
    return std::numeric_limits<Scalar>::infinity();
  if (analytic.size() == 0) return Scalar(0);
  const Scalar floor = std::sqrt(std::numeric_limits<Scalar>::epsilon());
  const Scalar largest = reference.cwiseAbs().template maxCoeff<Eigen::PropagateNaN>();
  const Scalar scale = std::isnan(largest) ? largest : std::max(largest, floor);
  return (analytic - reference).cwiseAbs().template maxCoeff<Eigen::PropagateNaN>() / scale;
}

/// The largest of `errors` (≥ 0), or NaN if any is NaN: a check whose product gave NaN must not
/// pass, and `std::max` keeps its first argument when the second is NaN. For a running worst:
/// `worst = worst_error({worst, error})`.
template <class Scalar>
[[nodiscard]] Scalar worst_error(std::initializer_list<Scalar> errors) {
  Scalar largest = 0;
  for (const Scalar error : errors) {
    if (std::isnan(error)) return error;
    largest = std::max(largest, error);
  }
  return largest;
}

namespace detail {

/// Aᵀ (state_dim × state_dim) and Bᵀ (control_dim × state_dim) from `sim.vjp`, one unit adjoint
/// per column.
template <Simulator Sim>
void vjp_transposes(const Sim& sim, const typename Sim::State& x, const typename Sim::Control& u,
                    Matrix<typename Sim::Scalar>& at, Matrix<typename Sim::Scalar>& bt) {
  using Scalar = typename Sim::Scalar;
  const Index n = sim.state_dim(), k = sim.control_dim();
  at.resize(n, n);
  bt.resize(k, n);
  typename Sim::State lambda = Sim::State::Zero(n), lambda_x;
  typename Sim::Control lambda_u;
  for (Index i = 0; i < n; ++i) {
    lambda.setZero();
    lambda(i) = Scalar(1);
    sim.vjp(x, u, lambda, &lambda_x, &lambda_u);
    check_vjp_output(&lambda_x, &lambda_u, n, k);
    // Entry by entry: GCC 12 -O3 warns (stringop-overread) on a vectorised column copy from a
    // fixed 2-vector into a column of run-time length.
    for (Index r = 0; r < n; ++r) at(r, i) = lambda_x(r);
    for (Index r = 0; r < k; ++r) bt(r, i) = lambda_u(r);
  }
}

}  // namespace detail

/// Where the worst error of a `check_jacobians` lies: an entry of A or B, as the simulator's
/// `jacobians` gave it or as its `vjp` did (Aᵀλ and Bᵀλ for λ = e_col), and the two values.
template <class Scalar>
struct WorstEntry {
  char matrix = 0;        ///< 'A' or 'B'; 0 before any comparison
  bool from_vjp = false;  ///< the value is the VJP's, not `jacobians`'s
  Index row = -1, col = -1;  ///< −1 for an empty product (no entry to name)
  Scalar analytic = 0, finite_difference = 0;
  Scalar error = 0;  ///< its relative error, the check's worst
};

/// Result of `check_jacobians`: worst relative errors of each analytic derivative.
///
/// Tolerances that hold for a correct, smooth simulator at the default step (the library's
/// own tests use them): `worst() < 1e-6` in double, `< 2e-2` in float (∛ε ≈ 5e-3 for float,
/// so truncation and round-off both sit near 1e-3 relative).
template <class Scalar>
struct JacobianCheck {
  Scalar state_jacobian_error = 0;    ///< A against finite differences in x (0 without A)
  Scalar control_jacobian_error = 0;  ///< B against finite differences in u (0 without B)
  Scalar vjp_error = 0;  ///< vjp against the finite-difference Aᵀ and Bᵀ, column by column
  bool has_jacobians = false;  ///< the simulator forms A and B (`SimulatorWithJacobians`)
  WorstEntry<Scalar> worst_entry;  ///< where `worst()` lies (`describe` puts it in words)
  [[nodiscard]] Scalar worst() const {
    return worst_error({state_jacobian_error, control_jacobian_error, vjp_error});
  }
  /// The tolerance above for `Scalar`: 2e-2 for float, 1e-6 for double.
  [[nodiscard]] static Scalar smooth_tolerance() {
    return std::numeric_limits<Scalar>::epsilon() > Scalar(1e-10) ? Scalar(2e-2) : Scalar(1e-6);
  }
};

namespace detail {

/// Compares `analytic` with `reference` (`relative_error`) and, when that is the worst error so
/// far (a NaN is worse than any number; on a tie the earlier stays), moves `worst` to its
/// largest difference (its first NaN). `from_vjp`: the matrices are Aᵀ or Bᵀ, whose entry
/// (r, c) is named (c, r).
template <class Scalar>
[[nodiscard]] Scalar compare_noting_worst(const Matrix<Scalar>& analytic,
                                          const Matrix<Scalar>& reference, char matrix,
                                          bool from_vjp, WorstEntry<Scalar>& worst) {
  const Scalar error = relative_error(analytic, reference);
  const bool worse = worst.matrix == 0 ||
                     (std::isnan(error) ? !std::isnan(worst.error) : error > worst.error);
  if (!worse) return error;
  worst = WorstEntry<Scalar>{matrix, from_vjp, -1, -1, 0, 0, error};
  if (analytic.rows() != reference.rows() || analytic.cols() != reference.cols() ||
      analytic.size() == 0)
    return error;
  Index r = -1, c = -1;
  const Matrix<Scalar> difference = (analytic - reference).cwiseAbs();
  for (Index k = difference.size() - 1; k >= 0; --k)  // column-major: the first NaN last
    if (std::isnan(difference(k))) {
      r = k % difference.rows();
      c = k / difference.rows();
    }
  if (r < 0) difference.maxCoeff(&r, &c);  // a NaN error may be ∞/∞, with no NaN entry
  worst.row = from_vjp ? c : r;
  worst.col = from_vjp ? r : c;
  worst.analytic = analytic(r, c);
  worst.finite_difference = reference(r, c);
  return error;
}

}  // namespace detail

/// Checks `sim.vjp` (for every unit adjoint) and, when the simulator has them, `sim.jacobians`
/// against central finite differences of `sim.step` at (x, u). Each derivative is measured
/// against the step itself, so a wrong B flags B alone, never a correct VJP.
template <Simulator Sim>
[[nodiscard]] JacobianCheck<typename Sim::Scalar> check_jacobians(
    const Sim& sim, const typename Sim::State& x, const typename Sim::Control& u,
    typename Sim::Scalar step = default_fd_step<typename Sim::Scalar>()) {
  using Scalar = typename Sim::Scalar;
  using State = typename Sim::State;
  using Control = typename Sim::Control;
  const Index n = sim.state_dim();

  State x_probe = x, next;
  Control u_probe = u;
  auto step_in_x = [&](const Vector<Scalar>& xv, Vector<Scalar>& out) {
    x_probe = xv;
    sim.step(x_probe, u, next);
    detail::check_step_output(next, n);
    out = next;
  };
  auto step_in_u = [&](const Vector<Scalar>& uv, Vector<Scalar>& out) {
    u_probe = uv;
    sim.step(x, u_probe, next);
    detail::check_step_output(next, n);
    out = next;
  };
  const Matrix<Scalar> fd_a = finite_difference_jacobian<Scalar>(step_in_x, x, n, step);
  const Matrix<Scalar> fd_b = finite_difference_jacobian<Scalar>(step_in_u, u, n, step);

  JacobianCheck<Scalar> result;
  if constexpr (SimulatorWithJacobians<Sim>) {
    typename Sim::StateJacobian a;
    typename Sim::ControlJacobian b;
    sim.jacobians(x, u, a, b);
    detail::check_jacobians_output(a, b, n, sim.control_dim());
    result.has_jacobians = true;
    result.state_jacobian_error = detail::compare_noting_worst<Scalar>(
        Matrix<Scalar>(a), fd_a, 'A', false, result.worst_entry);
    result.control_jacobian_error = detail::compare_noting_worst<Scalar>(
        Matrix<Scalar>(b), fd_b, 'B', false, result.worst_entry);
  }

  Matrix<Scalar> at, bt;
  detail::vjp_transposes(sim, x, u, at, bt);
  result.vjp_error = worst_error(
      {detail::compare_noting_worst<Scalar>(at, fd_a.transpose(), 'A', true, result.worst_entry),
       detail::compare_noting_worst<Scalar>(bt, fd_b.transpose(), 'B', true,
                                            result.worst_entry)});
  return result;
}

/// The worst error of `check` in words: "relative error 0.000909 at A(1, 0): -0.099 by
/// jacobians, -0.1 by finite differences" (rows and columns from 0).
template <class Scalar>
[[nodiscard]] std::string describe(const JacobianCheck<Scalar>& check) {
  const WorstEntry<Scalar>& w = check.worst_entry;
  if (w.matrix == 0) return "nothing compared";
  char text[256];
  const auto error = static_cast<double>(w.error);
  if (w.row < 0) {
    std::snprintf(text, sizeof text, "relative error %.3g in %c by %s", error, w.matrix,
                  w.from_vjp ? "the vjp" : "jacobians");
  } else {
    std::snprintf(text, sizeof text,
                  "relative error %.3g at %c(%ld, %ld): %.6g by %s, %.6g by finite differences",
                  error, w.matrix, static_cast<long>(w.row), static_cast<long>(w.col),
                  static_cast<double>(w.analytic), w.from_vjp ? "the vjp" : "jacobians",
                  static_cast<double>(w.finite_difference));
  }
  return text;
}

/// Worst relative disagreement between `sim.vjp` and the transposes of the simulator's own
/// `jacobians` at (x, u): both are analytic, so a consistent pair agrees to round-off (a
/// stronger statement than either one's agreement with finite differences).
template <SimulatorWithJacobians Sim>
[[nodiscard]] typename Sim::Scalar vjp_jacobian_mismatch(const Sim& sim,
                                                        const typename Sim::State& x,
                                                        const typename Sim::Control& u) {
  using Scalar = typename Sim::Scalar;
  typename Sim::StateJacobian a;
  typename Sim::ControlJacobian b;
  sim.jacobians(x, u, a, b);
  detail::check_jacobians_output(a, b, sim.state_dim(), sim.control_dim());
  Matrix<Scalar> at, bt;
  detail::vjp_transposes(sim, x, u, at, bt);
  return worst_error({relative_error<Scalar>(at, Matrix<Scalar>(a).transpose()),
                      relative_error<Scalar>(bt, Matrix<Scalar>(b).transpose())});
}

}  // namespace sbptt
