#pragma once
/// \file The Taylor test of a simulator's VJP: the twin of `check_jacobians` that needs no
/// step size and no scale. Finite differences compare a derivative with a difference quotient
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
/// wrong by any amount e leaves r(h) ≈ e·h, order → 1, once h is small enough for that term to
/// lead. The halving goes on until r(h) reaches the rounding of the difference,
///
///     ρ(h) = ε · Σᵢ |λᵢ| (|Pᵢ(x + Δx, u + Δu)| + |Pᵢ(x, u)|),
///
/// so an error is found wherever it exceeds rounding. A step that is linear along the direction
/// (a linear scene, or a spring chain) leaves r at rounding from the first h: its VJP agrees with
/// the exact difference to rounding, which the test reports as such.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <string>
#include <type_traits>
#include <vector>

#include "sbptt/core/concepts.hpp"
#include "sbptt/core/error.hpp"
#include "sbptt/core/rng.hpp"
#include "sbptt/core/simulator_output.hpp"

namespace sbptt {

/// The remainders of a `taylor_test`, one row per step h = h₀, h₀/2, … (see the file comment).
template <class Scalar>
struct TaylorTest {
  /// A remainder counts as above rounding when it exceeds this many times ρ(h); below, a
  /// rounding error of ρ moves the observed order by at most log₂(1 + 1/16) ≈ 0.09.
  static constexpr Scalar rounding_margin = 16;

  struct Row {
    Scalar step = 0;       ///< h
    Scalar remainder = 0;  ///< r(h)
    Scalar rounding = 0;   ///< ρ(h)
    Scalar first_order = 0;  ///< |⟨Aᵀλ, Δx⟩ + ⟨Bᵀλ, Δu⟩|: the change the VJP predicts
    [[nodiscard]] bool above_rounding() const { return remainder > rounding_margin * rounding; }
  };
  std::vector<Row> rows;

  /// log₂ r(hₖ)/r(hₖ₊₁) for each pair of rows whose both remainders are above rounding, in
  /// the order of falling h; NaN where a remainder is NaN.
  [[nodiscard]] std::vector<Scalar> orders() const {
    std::vector<Scalar> result;
    for (std::size_t k = 0; k + 1 < rows.size(); ++k) {
      const Row &larger = rows[k], &smaller = rows[k + 1];
      const bool has_nan = std::isnan(larger.remainder) || std::isnan(smaller.remainder);
      if (!has_nan && !(larger.above_rounding() && smaller.above_rounding())) break;
      result.push_back(std::log2(larger.remainder / smaller.remainder));
      if (has_nan) break;
    }
    return result;
  }

  /// The order at the smallest pair of steps above rounding: what the VJP's error shows once
  /// the step's curvature no longer leads. NaN when there is no such pair.
  [[nodiscard]] Scalar asymptotic_order() const {
    const std::vector<Scalar> all = orders();
    return all.empty() ? std::numeric_limits<Scalar>::quiet_NaN() : all.back();
  }

  /// The smallest r(h) / |⟨Aᵀλ, Δx⟩ + ⟨Bᵀλ, Δu⟩| over the rows, r(h) taken as at least the
  /// rounding margin times ρ(h) (below it the remainder is noise, and may be 0 by chance). A
  /// VJP whose predicted change along this direction is off by a relative e leaves r(h) ≥
  /// e·|prediction| − O(h²), so e is at most this bound. Sharp near the h where curvature and
  /// rounding balance (about √ε of a well-scaled step); NaN when a remainder is NaN.
  [[nodiscard]] Scalar relative_error_bound() const {
    Scalar bound = std::numeric_limits<Scalar>::infinity();
    for (const Row& row : rows) {
      if (std::isnan(row.remainder)) return row.remainder;
      const Scalar resolved = std::max(row.remainder, rounding_margin * row.rounding);
      if (row.first_order > Scalar(0)) bound = std::min(bound, resolved / row.first_order);
    }
    return bound;
  }

  /// The change the VJP predicts at h₀ stands above rounding, so the test can see it (an
  /// adjoint nearly orthogonal to the step's response leaves nothing to test).
  [[nodiscard]] bool conclusive() const {
    return !rows.empty() && rows.front().first_order > rounding_margin * rows.front().rounding;
  }

  /// r(h₀) is already at rounding: along this direction the step is linear (to rounding) and
  /// the VJP predicts its change to within `relative_error_bound()`.
  [[nodiscard]] bool exact_to_rounding() const {
    return !rows.empty() && !std::isnan(rows.front().remainder) && !rows.front().above_rounding();
  }

  /// The order a right VJP reaches: 2 less room for the rounding margin (a wrong one shows 1).
  static constexpr Scalar min_order = Scalar(1.8);

  /// The VJP passes: the test is conclusive, and the VJP is exact to rounding, or its
  /// asymptotic order is at least `min_order`, or its relative error bound is at most
  /// `tolerance`. The default 0 fails any error that shows above rounding; derivatives that
  /// are themselves finite differences (MuJoCo's) are off by about 1e-10 and need a tolerance.
  [[nodiscard]] bool passed(Scalar tolerance = 0) const {
    return conclusive() && (exact_to_rounding() || asymptotic_order() >= min_order ||
                            relative_error_bound() <= tolerance);
  }
};

/// Runs the Taylor test of `sim.vjp` at (x, u) along (dx, du) with the adjoint `lambda`,
/// halving h from `initial_step` until the remainder reaches rounding (at most `max_halvings`
/// times). Throws `InvalidArgument` for sizes other than the simulator's or a step that is not
/// finite and > 0.
template <Simulator Sim>
[[nodiscard]] TaylorTest<typename Sim::Scalar> taylor_test(
    const Sim& sim, const typename Sim::State& x, const typename Sim::Control& u,
    const typename Sim::State& dx, const typename Sim::Control& du,
    const typename Sim::State& lambda, typename Sim::Scalar initial_step = typename Sim::Scalar(0.1),
    int max_halvings = 60) {
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
  TaylorTest<Scalar> result;
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
    row.rounding = epsilon * lambda.cwiseAbs().dot(State(moved.cwiseAbs() + base.cwiseAbs()));
    row.first_order = std::abs(predicted);
    result.rows.push_back(row);
    if (!row.above_rounding()) break;
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
/// its size, so every entry of A and B takes part.
/// Costs about 2 × 40 steps and two VJPs in double, whatever the state's size (finite
/// differences of every entry cost 2(n + k) steps and n VJPs).
template <Simulator Sim>
[[nodiscard]] VjpTaylorTest<typename Sim::Scalar> taylor_test(const Sim& sim,
                                                              const typename Sim::State& x,
                                                              const typename Sim::Control& u,
                                                              std::uint64_t seed = 1) {
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
  return {taylor_test(sim, x, u, dx, Control(du * Scalar(0)), lambda),
          taylor_test(sim, x, u, State(dx * Scalar(0)), du, lambda)};
}

/// The test in words: "order 2.00 at h = 1.53e-06 (r falls from 2.13e-13 to 5.32e-14), 16
/// halvings above rounding (agrees to 9.9e-09 relative)", "exact to rounding: r(0.1) =
/// 4.03e-17, rounding 1.2e-15 (agrees to 1.3e-11 relative)", "inconclusive: …".
template <class Scalar>
[[nodiscard]] std::string describe(const TaylorTest<Scalar>& test) {
  if (test.rows.empty()) return "nothing compared";
  char text[256];
  const auto& first = test.rows.front();
  if (!test.conclusive()) {
    std::snprintf(text, sizeof text,
                  "inconclusive: the predicted change %.3g at h = %.3g is within rounding %.3g "
                  "(try another seed or a larger initial step)",
                  static_cast<double>(first.first_order), static_cast<double>(first.step),
                  static_cast<double>(first.rounding));
    return text;
  }
  if (test.exact_to_rounding()) {
    std::snprintf(text, sizeof text,
                  "exact to rounding: r(%.3g) = %.3g, rounding %.3g (agrees to %.2g relative)",
                  static_cast<double>(first.step), static_cast<double>(first.remainder),
                  static_cast<double>(first.rounding),
                  static_cast<double>(test.relative_error_bound()));
    return text;
  }
  const std::vector<Scalar> orders = test.orders();
  if (orders.empty()) {
    std::snprintf(text, sizeof text, "no order measured: r(%.3g) = %.3g, r(%.3g) = %.3g",
                  static_cast<double>(first.step), static_cast<double>(first.remainder),
                  static_cast<double>(test.rows.back().step),
                  static_cast<double>(test.rows.back().remainder));
    return text;
  }
  const auto& larger = test.rows[orders.size() - 1];
  const auto& smaller = test.rows[orders.size()];
  std::snprintf(text, sizeof text,
                "order %.2f at h = %.3g (r falls from %.3g to %.3g), %zu halvings above "
                "rounding (agrees to %.2g relative)",
                static_cast<double>(orders.back()), static_cast<double>(smaller.step),
                static_cast<double>(larger.remainder), static_cast<double>(smaller.remainder),
                orders.size(), static_cast<double>(test.relative_error_bound()));
  return text;
}

/// Both tests in words: "Aᵀλ: order 2.00 at …; Bᵀλ: exact to rounding: …".
template <class Scalar>
[[nodiscard]] std::string describe(const VjpTaylorTest<Scalar>& test) {
  return "Aᵀλ: " + describe(test.in_state) + "; Bᵀλ: " + describe(test.in_control);
}

}  // namespace sbptt
