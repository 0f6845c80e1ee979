// The Taylor test must see what it exists to see: a remainder that falls as h² for a right VJP
// (against its closed form), order 1 for a VJP wrong by a relative 1e-9 that finite differences
// report at 1e-9 but do not flag, exactness on a linear step, and no verdict where the predicted
// change hides in rounding.
#include <cmath>
#include <limits>
#include <stdexcept>

#include <catch2/catch.hpp>

#include "sbptt/core/finite_difference.hpp"
#include "sbptt/core/taylor_test.hpp"
#include "sbptt/sim/autodiff.hpp"
#include "sbptt/sim/cartpole.hpp"
#include "sbptt/sim/linear.hpp"

using namespace sbptt;

namespace {

/// P(x, u) = (x₀², x₁ u₀): along (δ, 0) with λ = (λ₀, 0) the remainder is exactly λ₀ δ₀² h².
struct Square {
  using Scalar = double;
  using State = Eigen::Vector2d;
  using Control = Eigen::Matrix<double, 1, 1>;
  bool nan_beyond_one = false;  ///< answer NaN for |x₀| > 1, as a simulator that refuses a state
  [[nodiscard]] Index state_dim() const { return 2; }
  [[nodiscard]] Index control_dim() const { return 1; }
  void step(const State& x, const Control& u, State& next) const {
    next << x(0) * x(0), x(1) * u(0);
    if (nan_beyond_one && std::abs(x(0)) > 1) next(0) = std::numeric_limits<double>::quiet_NaN();
  }
  void vjp(const State& x, const Control& u, const State& lambda, State* lambda_x,
           Control* lambda_u) const {
    if (lambda_x) *lambda_x << 2 * x(0) * lambda(0), u(0) * lambda(1);
    if (lambda_u) *lambda_u << x(1) * lambda(1);
  }
};

/// A simulator whose Bᵀλ is `factor` times the true one.
template <class Sim>
struct ScaledControlVjp {
  using Scalar = typename Sim::Scalar;
  using State = typename Sim::State;
  using Control = typename Sim::Control;
  Sim sim;
  Scalar factor;
  [[nodiscard]] Index state_dim() const { return sim.state_dim(); }
  [[nodiscard]] Index control_dim() const { return sim.control_dim(); }
  void step(const State& x, const Control& u, State& next) const { sim.step(x, u, next); }
  void vjp(const State& x, const Control& u, const State& lambda, State* lambda_x,
           Control* lambda_u) const {
    sim.vjp(x, u, lambda, lambda_x, lambda_u);
    if (lambda_u) *lambda_u *= factor;
  }
};

/// Three masses joined by springs of k = 10⁶ with a cubic hardening term, the first pushed by
/// u; semi-implicit Euler with dt = 0.01. State (p₀, v₀, p₁, v₁, p₂, v₂), control u.
struct StiffChain {
  static constexpr int kStateSize = 6, kControlSize = 1;
  double stiffness = 1e6, hardening = 1e6;
  template <class T>
  void step(const ColumnOf<T, 6>& x, const ColumnOf<T, 1>& u, ColumnOf<T, 6>& next) const {
    const T dt = constant<T>(0.01);
    T force[3] = {u(0), T(0), T(0)};
    for (int i = 0; i < 2; ++i) {
      const T stretch = x(2 * i + 2) - x(2 * i);
      const T pull = constant<T>(stiffness) * stretch +
                     constant<T>(hardening) * stretch * stretch * stretch;
      force[i] += pull;
      force[i + 1] -= pull;
    }
    for (int i = 0; i < 3; ++i) {
      next(2 * i + 1) = x(2 * i + 1) + dt * force[i];
      next(2 * i) = x(2 * i) + dt * next(2 * i + 1);
    }
  }
};

CartPole<double, 4>::State cartpole_state() {
  CartPole<double, 4>::State x;
  Rng rng(5);
  for (Index i = 0; i < x.size(); ++i) x(i) = rng.normal();
  return x;
}

}  // namespace

TEST_CASE("Taylor test: the remainder of x² is λ δ² h², order 2", "[core][taylor]") {
  const Square sim;
  const Square::State x(0.3, -0.7), dx(0.8, 0.0), lambda(1.5, 0.0);
  const Square::Control u(2.0), du(0.0);
  const auto test = taylor_test(sim, x, u, dx, du, lambda);
  REQUIRE(test.rows.size() >= 10);
  for (const auto& row : test.rows) {
    if (!row.above_rounding()) continue;
    const double exact = 1.5 * 0.8 * 0.8 * row.step * row.step;
    CHECK(std::abs(row.remainder - exact) <= 1e-6 * exact + 64 * row.rounding);
  }
  for (const double order : test.orders()) CHECK(std::abs(order - 2) < 0.02);
  CHECK(test.conclusive());
  CHECK_FALSE(test.exact_to_rounding());
  CHECK(test.passed());
  CHECK_THAT(describe(test), Catch::Matchers::StartsWith("order 2.0"));
}

TEST_CASE("Taylor test: a right VJP passes, one wrong by 1e-9 fails in order 1",
          "[core][taylor]") {
  const CartPole<double, 4> sim;
  const auto x = cartpole_state();
  const CartPole<double, 4>::Control u(0.3);
  for (const std::uint64_t seed : {1, 2, 3, 4, 5}) {
    const auto right = taylor_test(sim, x, u, seed);
    INFO("seed " << seed << ": " << describe(right));
    CHECK(right.passed());
    CHECK(std::abs(right.in_state.asymptotic_order() - 2) < 0.2);
    CHECK(right.in_state.relative_error_bound() < 1e-6);
  }
  // Finite differences measure the planted error (1.06e-9) but pass it under their 1e-6.
  const ScaledControlVjp<CartPole<double, 4>> wrong{sim, 1 + 1e-9};
  const auto fd = check_jacobians(wrong, x, u);
  CHECK(fd.worst() < JacobianCheck<double>::smooth_tolerance());
  int failed = 0;
  for (const std::uint64_t seed : {1, 2, 3, 4, 5}) {
    const auto test = taylor_test(wrong, x, u, seed);
    INFO("seed " << seed << ": " << describe(test));
    CHECK(test.in_state.passed());
    if (!test.in_control.passed()) {
      ++failed;
      CHECK(std::abs(test.in_control.asymptotic_order() - 1) < 0.1);
    }
    // The bound holds the planted error, whatever the verdict.
    CHECK(test.in_control.relative_error_bound() >= 0.5e-9);
    CHECK(test.in_control.relative_error_bound() <= 2e-9);
  }
  CHECK(failed >= 4);
  // A tolerance passes what the bound holds under it.
  CHECK(taylor_test(wrong, x, u).passed(1e-8));
  CHECK_FALSE(taylor_test(wrong, x, u).passed(1e-10));
  const auto flipped = taylor_test(ScaledControlVjp<CartPole<double, 4>>{sim, -1.0}, x, u);
  CHECK_FALSE(flipped.passed());
  CHECK(std::abs(flipped.in_control.relative_error_bound() - 2) < 1e-2);
}

TEST_CASE("Taylor test: a linear step is exact to rounding; a wrong B is not", "[core][taylor]") {
  LinearSystem<double, 3, 1>::StateJacobian a;
  a << 0.9, 0.2, 0.0, -0.1, 1.1, 0.3, 0.0, 0.4, 0.8;
  LinearSystem<double, 3, 1>::ControlJacobian b;
  b << 0.5, 2.0, -1.0;
  const LinearSystem<double, 3, 1> sim(a, b);
  const Eigen::Vector3d x(1.0, -2.0, 0.5);
  const Eigen::Matrix<double, 1, 1> u(0.7);
  const auto exact = taylor_test(sim, x, u);
  INFO(describe(exact));
  CHECK(exact.passed());
  CHECK(exact.in_state.exact_to_rounding());
  CHECK(exact.in_control.exact_to_rounding());
  CHECK(exact.in_state.rows.size() == 1);
  CHECK(exact.in_control.relative_error_bound() < 1e-12);

  const auto wrong = taylor_test(ScaledControlVjp<LinearSystem<double, 3, 1>>{sim, 1 + 1e-9}, x, u);
  INFO(describe(wrong));
  CHECK(wrong.in_state.passed());
  CHECK_FALSE(wrong.in_control.passed());
  CHECK(std::abs(wrong.in_control.asymptotic_order() - 1) < 0.05);
}

TEST_CASE("Taylor test: a stiff chain passes without a step to choose", "[core][taylor]") {
  const AutoDiffSimulator<StiffChain> sim{StiffChain{}};
  AutoDiffSimulator<StiffChain>::State x;
  x << 0.0, 0.1, 0.012, -0.2, 0.019, 0.05;
  const AutoDiffSimulator<StiffChain>::Control u(1.0);
  for (const std::uint64_t seed : {1, 2, 3}) {
    const auto test = taylor_test(sim, x, u, seed);
    INFO("seed " << seed << ": " << describe(test));
    CHECK(test.passed());
  }
  const auto wrong = taylor_test(ScaledControlVjp<AutoDiffSimulator<StiffChain>>{sim, 1 + 1e-6},
                                 x, u);
  INFO(describe(wrong));
  CHECK_FALSE(wrong.passed());
}

TEST_CASE("Taylor test: no verdict without a visible change, none through NaN",
          "[core][taylor]") {
  Square sim;
  const Square::State x(0.3, -0.7), dx(0.8, 0.5);
  const Square::Control u(2.0), du(1.0);
  const auto blind = taylor_test(sim, x, u, dx, du, Square::State::Zero());
  CHECK_FALSE(blind.conclusive());
  CHECK_FALSE(blind.passed());
  CHECK_THAT(describe(blind), Catch::Matchers::StartsWith("inconclusive"));

  sim.nan_beyond_one = true;
  const auto refused = taylor_test(sim, x, u, Square::State(2.0, 0.0), du, Square::State(1, 1), 1.0);
  CHECK(std::isnan(refused.rows.front().remainder));
  CHECK(std::isnan(refused.relative_error_bound()));
  CHECK_FALSE(refused.passed());
  CHECK_THAT(describe(refused), Catch::Matchers::Contains("nan"));
}

TEST_CASE("Taylor test: sizes and steps out of range are refused", "[core][taylor]") {
  const Square sim;
  const Square::State x(0.3, -0.7);
  const Square::Control u(2.0);
  const Eigen::VectorXd three = Eigen::VectorXd::Ones(3);
  const LinearSystem<double> dynamic(Eigen::MatrixXd::Identity(2, 2), Eigen::MatrixXd::Ones(2, 1));
  CHECK_THROWS_WITH(taylor_test(dynamic, Eigen::VectorXd(x), Eigen::VectorXd(u), three,
                                Eigen::VectorXd(u), Eigen::VectorXd(x)),
                    Catch::Matchers::Contains("x, dx and lambda have sizes 2, 3 and 2; expected "
                                              "state_dim() = 2"));
  for (const double step : {0.0, -1.0, std::numeric_limits<double>::quiet_NaN()})
    CHECK_THROWS_WITH(taylor_test(sim, x, u, x, u, x, step),
                      Catch::Matchers::Contains("initial_step = ") &&
                          Catch::Matchers::Contains("expected a finite number > 0"));
}
