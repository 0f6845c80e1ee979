#pragma once
/// \file The Taylor test of a simulator's VJP: the twin of `check_jacobians` with no
/// difference step to tune. Finite differences compare a derivative with a difference quotient
/// at one step, whose truncation and rounding errors depend on the scene's scales; a stiff scene
/// can fail them with correct derivatives. The Taylor test instead watches how a remainder falls.
///
/// For a direction (δ, η) and an adjoint λ, with P the step and h = h₀, h₀/2, h₀/4, …:
///
///     Δx = (x + hδ) − x,  Δu = (u + hη) − u       (the perturbations as actually rounded)
///     r(h) = | ⟨λ, P(x + Δx, u + Δu) − P(x, u)⟩ − (⟨Aᵀλ, Δx⟩ + ⟨Bᵀλ, Δu⟩) |
///
/// with Aᵀλ and Bᵀλ from `sim.vjp`. For a twice differentiable step r(h) = O(h²) when the VJP
/// is right, so each halving of h divides r by 4 (observed order log₂ r(h)/r(h/2) → 2). A VJP
/// wrong by a relative e leaves r(h) ≈ |e·p·h + c·h²| (p the prediction's slope, c the
/// curvature), order → 1 once h is small enough for the first term to lead. The halving goes
/// on until two remainders in a row reach the rounding of the difference,
///
///     ρ(h) = ε · Σᵢ |λᵢ| (|Pᵢ(x + Δx, u + Δu)| + |Pᵢ(x, u)|),
///
/// (one alone may be where c·h² cancels e·p·h), so an error is found where its term exceeds
/// rounding at some h below the curvature's lead. A step that is linear along the direction (a
/// linear scene, or a spring chain) leaves r at rounding from the first h: its VJP agrees with
/// the exact difference to the test's resolution, which the test reports as such. ρ counts the
/// rounding of P's values, not of the work inside the step: a step with cancellation inside
/// leaves r flat above ρ, which the test reports as inconclusive.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <string>
#include <type_traits>
#include <vector>

#include "sbptt/core/concepts.hpp"
#include "sbptt/core/error.hpp"
#include "sbptt/core/finite_difference.hpp"
#include "sbptt/core/rng.hpp"
#include "sbptt/core/simulator_output.hpp"

namespace sbptt {

/// The remainders of a `taylor_test`, one row per step h = h₀, h₀/2, … (see the file comment).
template <class Scalar>
struct TaylorTest {
  /// A remainder counts as above rounding when it exceeds this many times ρ(h). Both
  /// remainders of a pair then carry at most 1/16 of rounding, which moves their order by at
  /// most log₂(17/15) ≈ 0.18 (as long as ρ bounds the rounding).
  static constexpr Scalar rounding_margin = 16;
  /// The order a right VJP reaches: 2 less the rounding margin's 0.18 (a wrong one shows 1).
  static constexpr Scalar min_order = Scalar(1.8);
  /// How far log₂ of the measured change's ratio over a pair may stray from the prediction's
  /// (which halves exactly): beyond it the step's own rounding, not its slope, moves the change.
  static constexpr Scalar halving_slack = Scalar(0.2);

  struct Row {
    Scalar step = 0;             ///< h
    Scalar remainder = 0;        ///< r(h)
    Scalar rounding = 0;         ///< ρ(h)
    Scalar predicted_change = 0;  ///< |⟨Aᵀλ, Δx⟩ + ⟨Bᵀλ, Δu⟩|: what the VJP predicts
    Scalar measured_change = 0;   ///< |⟨λ, P(x + Δx, u + Δu) − P(x, u)⟩|: what the step did
    [[nodiscard]] bool above_rounding() const { return remainder > rounding_margin * rounding; }
  };
  /// Every step tried, until two in a row reached rounding (one alone may be a zero of the
  /// remainder, where curvature cancels an error), a NaN, or the last halving.
  std::vector<Row> rows;

  /// log₂ r(hₖ)/r(hₖ₊₁) for each pair of neighbouring rows both above rounding, in the order of
  /// falling h.
  [[nodiscard]] std::vector<Scalar> orders() const {
    std::vector<Scalar> result;
    for (std::size_t k = 0; k + 1 < rows.size(); ++k)
      if (pair_above_rounding(k)) result.push_back(order_at(k));
    return result;
  }

  /// The order of the last pair above rounding, at the smallest steps: what the VJP's error
  /// shows once the step's curvature no longer leads. NaN without such a pair or after a NaN.
  [[nodiscard]] Scalar asymptotic_order() const {
    const std::ptrdiff_t k = last_pair();
    return k < 0 || has_nan() ? std::numeric_limits<Scalar>::quiet_NaN()
                              : order_at(static_cast<std::size_t>(k));
  }

  /// The two first remainders are at rounding: along this direction the step is linear (to
  /// rounding) and the VJP predicts its change to within `relative_error_estimate()`.
  [[nodiscard]] bool exact_to_rounding() const {
    return rows.size() >= 2 && !has_nan() && !rows[0].above_rounding() &&
           !rows[1].above_rounding();
  }

  /// The smallest relative error of the prediction that shows above rounding at h₀:
  /// rounding_margin·ρ(h₀)/|prediction(h₀)|.
  [[nodiscard]] Scalar resolution() const {
    if (rows.empty()) return std::numeric_limits<Scalar>::infinity();
    return rounding_margin * rows.front().rounding / rows.front().predicted_change;
  }

  /// The coarsest resolution the test accepts: the tolerance `check_jacobians` applies to a
  /// smooth step (1e-6 in double, 2e-2 in float).
  [[nodiscard]] static Scalar max_resolution() { return JacobianCheck<Scalar>::smooth_tolerance(); }

  /// Over the pair that gives the asymptotic order, the step's change halved with h as the
  /// prediction did. A step with cancellation inside it (rounding far above ρ) stops doing so:
  /// its change sticks at a multiple of its own rounding, and r then follows the prediction.
  [[nodiscard]] bool change_halves() const {
    const std::ptrdiff_t k = last_pair();
    if (k < 0) return false;
    const Row& larger = rows[static_cast<std::size_t>(k)];
    const Row& smaller = rows[static_cast<std::size_t>(k) + 1];
    const Scalar measured = std::log2(larger.measured_change / smaller.measured_change);
    const Scalar predicted = std::log2(larger.predicted_change / smaller.predicted_change);
    return std::abs(measured - predicted) <= halving_slack;
  }

  /// The test can tell a right VJP from a wrong one: no NaN, a resolution no coarser than
  /// `max_resolution()` (an adjoint nearly orthogonal to the step's response, or float's
  /// rounding, leaves the prediction too close to rounding), and, unless exact to rounding, a
  /// change that still halves at the smallest steps (`change_halves`).
  [[nodiscard]] bool conclusive() const {
    if (rows.empty() || has_nan()) return false;
    if (!(resolution() <= max_resolution())) return false;
    return exact_to_rounding() || change_halves();
  }

  /// The VJP's relative error along this direction, as the remainder shows it: at most
  /// `resolution()` when exact to rounding (the step is linear there, so r = e·|prediction|);
  /// else r/|prediction| at the smallest step above rounding, which is e up to the curvature's
  /// share c·h/|prediction| there (an estimate, not a bound: curvature may oppose the error).
  /// NaN after a NaN.
  [[nodiscard]] Scalar relative_error_estimate() const {
    if (rows.empty() || has_nan()) return std::numeric_limits<Scalar>::quiet_NaN();
    if (exact_to_rounding()) return resolution();
    for (auto row = rows.rbegin(); row != rows.rend(); ++row)
      if (row->above_rounding()) return row->remainder / row->predicted_change;
    return std::numeric_limits<Scalar>::quiet_NaN();
  }

  /// The VJP passes: the test is conclusive, and the VJP is exact to rounding, or its
  /// asymptotic order is at least `min_order`, or its relative error estimate is at most
  /// `tolerance`. The default 0 fails any error that shows above rounding; derivatives that
  /// are themselves finite differences (MuJoCo's) are off by about 1e-10 and need a tolerance.
  [[nodiscard]] bool passed(Scalar tolerance = 0) const {
    return conclusive() && (exact_to_rounding() || asymptotic_order() >= min_order ||
                            relative_error_estimate() <= tolerance);
  }

  /// Index k of the last pair (k, k + 1) both above rounding; −1 for none.
  [[nodiscard]] std::ptrdiff_t last_pair() const {
    for (std::size_t k = rows.size(); k >= 2; --k)
      if (pair_above_rounding(k - 2)) return static_cast<std::ptrdiff_t>(k - 2);
    return -1;
  }

  [[nodiscard]] bool has_nan() const {
    return std::any_of(rows.begin(), rows.end(), [](const Row& row) {
      return std::isnan(row.remainder) || std::isnan(row.rounding);
    });
  }

private:
  [[nodiscard]] bool pair_above_rounding(std::size_t k) const {
    return rows[k].above_rounding() && rows[k + 1].above_rounding();
  }
  [[nodiscard]] Scalar order_at(std::size_t k) const {
    return std::log2(rows[k].remainder / rows[k + 1].remainder);
  }
};

/// Runs the Taylor test of `sim.vjp` at (x, u) along (dx, du) with the adjoint `lambda`,
/// halving h from `initial_step` until two remainders in a row reach rounding (at most
/// `max_halvings` times). Throws `InvalidArgument` for sizes other than the simulator's or a
/// step that is not finite and > 0.
template <Simulator Sim>
[[nodiscard]] TaylorTest<typename Sim::Scalar> taylor_test(
    const Sim& sim, const typename Sim::State& x, const typename Sim::Control& u,
    const typename Sim::State& dx, const typename Sim::Control& du,
    const typename Sim::State& lambda,
    typename Sim::Scalar initial_step = typename Sim::Scalar(0.1), int max_halvings = 60) {
  using Scalar = typename Sim::Scalar;
  using State = typename Sim::State;
  using Control = typename Sim::Control;
  const Index n = sim.state_dim(), k = sim.control_dim();
  detail::require(x.size() == n && dx.size() == n && lambda.size() == n,
                  "taylor_test: x, dx and lambda have sizes ", x.size(), ", ", dx.size(), " and ",
                  lambda.size(), "; expected state_dim() = ", n);
  detail::require(u.size() == k && du.size() == k, "taylor_test: u and du have sizes ", u.size(),
                  " and ", du.size(), "; expected control_dim() = ", k);
  detail::require(std::isfinite(initial_step) && initial_step > Scalar(0),
                  "taylor_test: initial_step = ", initial_step, "; expected a finite number > 0");
  detail::require(max_halvings >= 1, "taylor_test: max_halvings = ", max_halvings,
                  "; expected at least 1");

  State base, moved, lambda_x;
  Control lambda_u;
  sim.step(x, u, base);
  detail::check_step_output(base, n);
  sim.vjp(x, u, lambda, &lambda_x, &lambda_u);
  detail::check_vjp_output(&lambda_x, &lambda_u, n, k);

  const Scalar epsilon = std::numeric_limits<Scalar>::epsilon();
  const State lambda_abs = lambda.cwiseAbs();
  const Scalar base_rounding = lambda_abs.dot(State(base.cwiseAbs()));  // the same at every h
  TaylorTest<Scalar> result;
  int at_rounding_in_a_row = 0;
  Scalar h = initial_step;
  for (int halving = 0; halving <= max_halvings; ++halving, h /= Scalar(2)) {
    const State x_moved = x + h * dx;
    const Control u_moved = u + h * du;
    sim.step(x_moved, u_moved, moved);
    detail::check_step_output(moved, n);
    const Scalar predicted = lambda_x.dot(State(x_moved - x)) + lambda_u.dot(Control(u_moved - u));
    const Scalar change = lambda.dot(State(moved - base));
    typename TaylorTest<Scalar>::Row row;
    row.step = h;
    row.remainder = std::abs(change - predicted);
    row.rounding = epsilon * (lambda_abs.dot(State(moved.cwiseAbs())) + base_rounding);
    row.predicted_change = std::abs(predicted);
    row.measured_change = std::abs(change);
    result.rows.push_back(row);
    if (std::isnan(row.remainder) || std::isnan(row.rounding)) break;
    at_rounding_in_a_row = row.above_rounding() ? 0 : at_rounding_in_a_row + 1;
    if (at_rounding_in_a_row == 2) break;
  }
  return result;
}

/// The Taylor tests of Aᵀλ and of Bᵀλ, each along its own direction: in a mixed direction the
/// larger of the two changes would hide an error in the smaller (a stiff A beside a B of dt).
template <class Scalar>
struct VjpTaylorTest {
  TaylorTest<Scalar> in_state;    ///< along (δ, 0): tests Aᵀλ
  TaylorTest<Scalar> in_control;  ///< along (0, η): tests Bᵀλ
  [[nodiscard]] bool passed(Scalar tolerance = 0) const {
    return in_state.passed(tolerance) && in_control.passed(tolerance);
  }
};

/// The Taylor tests of `sim.vjp` at (x, u) along seeded random directions: δᵢ = zᵢ·max(1,
/// |xᵢ|), ηⱼ = zⱼ·max(1, |uⱼ|) and λ = z, each z drawn from N(0, I) and rescaled to |z|² =
/// its size, so every entry of A and B takes part. Costs two VJPs and at most 2 × (2 +
/// max_halvings) steps, whatever the state's size (finite differences of every entry cost
/// 2(n + k) steps and n VJPs). A scene whose step is defined only near (x, u) (a joint limit,
/// a positive mass) takes a smaller `initial_step`.
template <Simulator Sim>
[[nodiscard]] VjpTaylorTest<typename Sim::Scalar> taylor_test(
    const Sim& sim, const typename Sim::State& x, const typename Sim::Control& u,
    std::uint64_t seed = 1, typename Sim::Scalar initial_step = typename Sim::Scalar(0.1),
    int max_halvings = 60) {
  using Scalar = typename Sim::Scalar;
  using State = typename Sim::State;
  using Control = typename Sim::Control;
  Rng rng(seed);
  // z ~ N(0, I) rescaled to |z|² = size, so that no draw (a lone control's above all) is tiny.
  auto draw = [&](const auto& at) {
    std::remove_cvref_t<decltype(at)> v = at;
    for (Index i = 0; i < v.size(); ++i) v(i) = static_cast<Scalar>(rng.normal());
    if (v.size() > 0) v *= std::sqrt(static_cast<Scalar>(v.size())) / v.norm();
    for (Index i = 0; i < v.size(); ++i) v(i) *= std::max(Scalar(1), std::abs(at(i)));
    return v;
  };
  const State dx = draw(x), lambda = draw(State(x * Scalar(0)));
  const Control du = draw(u);
  return {taylor_test(sim, x, u, dx, Control(du * Scalar(0)), lambda, initial_step, max_halvings),
          taylor_test(sim, x, u, State(dx * Scalar(0)), du, lambda, initial_step, max_halvings)};
}

/// The test in words: "order 2.00 at h = 1.53e-06 (r falls from 2.13e-13 to 5.32e-14), 16
/// pairs above rounding, relative error about 1e-08", "exact to rounding: r(0.1) = 4.03e-17,
/// rounding 1.2e-15, relative error at most 1.3e-11", "inconclusive: …".
template <class Scalar>
[[nodiscard]] std::string describe(const TaylorTest<Scalar>& test) {
  if (test.rows.empty()) return "nothing compared";
  char text[320];
  const auto& first = test.rows.front();
  const auto value = [](Scalar x) { return static_cast<double>(x); };
  if (test.has_nan()) {
    std::snprintf(text, sizeof text, "inconclusive: the step or the VJP gave NaN at h = %.3g",
                  value(test.rows.back().step));
  } else if (!(test.resolution() <= test.max_resolution())) {
    std::snprintf(text, sizeof text,
                  "inconclusive: at h = %.3g the predicted change %.3g resolves relative errors "
                  "only down to %.2g (16 times rounding %.3g over it), expected at most %.2g: "
                  "try another seed, a larger initial step, or double",
                  value(first.step), value(first.predicted_change), value(test.resolution()),
                  value(first.rounding), value(test.max_resolution()));
  } else if (test.exact_to_rounding()) {
    std::snprintf(text, sizeof text,
                  "exact to rounding: r(%.3g) = %.3g and r(%.3g) = %.3g, rounding %.3g; "
                  "relative error at most %.2g",
                  value(first.step), value(first.remainder), value(test.rows[1].step),
                  value(test.rows[1].remainder), value(first.rounding),
                  value(test.relative_error_estimate()));
  } else if (test.last_pair() < 0) {
    std::snprintf(text, sizeof text,
                  "no order measured: no two neighbouring steps above rounding between h = "
                  "%.3g and %.3g",
                  value(first.step), value(test.rows.back().step));
  } else {
    const auto k = static_cast<std::size_t>(test.last_pair());
    const auto& larger = test.rows[k];
    const auto& smaller = test.rows[k + 1];
    std::snprintf(text, sizeof text,
                  "%sorder %.2f at h = %.3g (r falls from %.3g to %.3g), %zu pairs above "
                  "rounding, relative error about %.2g%s",
                  test.conclusive() ? "" : "inconclusive: ", value(test.asymptotic_order()),
                  value(smaller.step), value(larger.remainder), value(smaller.remainder),
                  test.orders().size(), value(test.relative_error_estimate()),
                  test.conclusive() ? ""
                                    : ": there the step's change no longer halves with h, so "
                                      "its own rounding, far above the estimate (cancellation "
                                      "inside it), decides r");
  }
  return text;
}

/// Both tests in words: "Aᵀλ: order 2.00 at …; Bᵀλ: exact to rounding: …".
template <class Scalar>
[[nodiscard]] std::string describe(const VjpTaylorTest<Scalar>& test) {
  return "Aᵀλ: " + describe(test.in_state) + "; Bᵀλ: " + describe(test.in_control);
}

}  // namespace sbptt
