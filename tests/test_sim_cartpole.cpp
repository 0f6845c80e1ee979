// Tests of the multi-pole cart pole (include/sbptt/sim/cartpole.hpp) against independent
// truth: central finite differences, the Taylor remainder, the paper's §5 rollout values,
// exact equilibria, float-vs-double and fixed-vs-dynamic agreement, and concurrent use.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <numbers>
#include <thread>
#include <vector>

#include "sbptt/objectives/cartpole.hpp"
#include "sbptt/bptt/objective.hpp"
#include "sbptt/core/concepts.hpp"
#include "sbptt/core/finite_difference.hpp"
#include "sbptt/core/rng.hpp"
#include "sbptt/sim/cartpole.hpp"
#include "support/taylor_remainder.hpp"

using sbptt::CartPole;
using sbptt::Index;
using sbptt::testing::taylor_remainder;

namespace {

constexpr double kPi = std::numbers::pi;

static_assert(sbptt::static_assert_simulator<CartPole<double, 1>>());
static_assert(sbptt::static_assert_simulator<CartPole<double, 4>>());
static_assert(sbptt::static_assert_simulator<CartPole<float, 2>>());
static_assert(sbptt::static_assert_simulator<CartPole<double, Eigen::Dynamic>>());
static_assert(CartPole<double, 3>::State::RowsAtCompileTime == 8);
static_assert(CartPole<double, 3>::StateJacobian::ColsAtCompileTime == 8);
static_assert(CartPole<double, 3>::Control::RowsAtCompileTime == 1);

/// A state with angles anywhere on the circle and brisk velocities: the Jacobians must hold
/// everywhere, not only near the paper's initial distribution.
template <class Sim>
typename Sim::State random_state(const Sim& sim, sbptt::Rng& rng) {
  typename Sim::State x(sim.state_dim());
  x(0) = rng.uniform(-2, 2);
  x(1) = rng.uniform(-3, 3);
  for (Index i = 0; i < sim.poles(); ++i) {
    x(2 + 2 * i) = rng.uniform(-kPi, 2 * kPi);
    x(3 + 2 * i) = rng.uniform(-6, 6);
  }
  return x;
}

/// The objective formula of objective.hpp, evaluated by a plain rollout (independent of the
/// engine): Σ_{n∈S} w ℓ(x_n) + ρ/(m k) Σ_n ‖c_n‖², with controls from `force(n)`.
template <class Sim, class Loss, class Force>
double rollout_objective(const Sim& sim, const sbptt::Objective<Loss>& objective,
                         typename Sim::State x, Force force, Index steps) {
  double state_part = 0, control_sq = 0;
  typename Sim::Control u;
  for (Index n = 0; n < steps; ++n) {
    u(0) = force(n);
    control_sq += u.squaredNorm();
    sim.step(x, u, x);
    if (objective.timing == sbptt::LossTiming::Continuous || n + 1 == steps) {
      state_part += objective.step_weight * objective.state_loss(x, nullptr);
    }
  }
  return state_part + objective.control_weight * control_sq /
                          static_cast<double>(steps * sim.control_dim());
}

template <class Sim>
void check_random_jacobians(const Sim& sim, std::uint64_t seed) {
  sbptt::Rng rng(seed);
  for (int sample = 0; sample < 20; ++sample) {
    const auto x = random_state(sim, rng);
    typename Sim::Control u;
    u(0) = rng.uniform(-10, 10);
    const auto check = sbptt::check_jacobians(sim, x, u);
    INFO("sample " << sample << ", poles " << sim.poles() << ": A " << check.state_jacobian_error
                    << ", B " << check.control_jacobian_error << ", vjp " << check.vjp_error);
    CHECK(check.state_jacobian_error <= 1e-6);
    CHECK(check.control_jacobian_error <= 1e-6);
    CHECK(check.vjp_error <= 1e-6);
    CHECK(sbptt::vjp_jacobian_mismatch(sim, x, u) <= 1e-12);
  }
}

/// At 20 seeded states, the Taylor remainder at h over that at h/2 is 4 ± 0.5 (O(h²)).
void check_taylor_ratios(const CartPole<double, 4>& sim, std::uint64_t seed) {
  sbptt::Rng rng(seed);
  for (int sample = 0; sample < 20; ++sample) {
    const auto x = random_state(sim, rng);
    const CartPole<double, 4>::Control u(rng.uniform(-5, 5));
    const CartPole<double, 4>::State dx = random_state(sim, rng).normalized();
    const CartPole<double, 4>::Control du(rng.uniform(-1, 1));
    for (const double h : {1e-2, 1e-3}) {
      const double ratio =
          taylor_remainder(sim, x, u, dx, du, h) / taylor_remainder(sim, x, u, dx, du, h / 2);
      INFO("sample " << sample << ", h = " << h << ", ratio = " << ratio);
      CHECK(ratio >= 3.5);
      CHECK(ratio <= 4.5);
    }
  }
}

}  // namespace

TEST_CASE("CartPole: constructor rejects bad options with a message naming the value",
          "[sim][cartpole]") {
  using Catch::Matchers::Contains;
  sbptt::CartPoleOptions bad;
  bad.horizon = 0;
  CHECK_THROWS_WITH(CartPole<>(bad), Contains("horizon = 0"));
  bad = {};
  bad.horizon = std::nan("");
  CHECK_THROWS_AS(CartPole<>(bad), sbptt::InvalidArgument);
  bad = {};
  bad.steps = 0;
  CHECK_THROWS_WITH(CartPole<>(bad), Contains("steps = 0"));
  bad = {};
  bad.total_mass = -1;
  CHECK_THROWS_WITH(CartPole<>(bad), Contains("total_mass = -1"));
  bad = {};
  bad.pole_mass = 2.0;  // 3m ≥ 4M makes the denominator l(4/3 − m cos²θ/M) vanish
  CHECK_THROWS_WITH(CartPole<>(bad), Contains("pole_mass = 2"));
  bad = {};
  bad.gravity = INFINITY;
  CHECK_THROWS_WITH(CartPole<>(bad), Contains("gravity = inf"));
  CHECK_THROWS_WITH((CartPole<double, Eigen::Dynamic>(0)), Contains("poles = 0"));
  CHECK_THROWS_WITH((CartPole<double, 2>(3)), Contains("poles = 3"));

  const CartPole<double, Eigen::Dynamic> dynamic(2);
  Eigen::VectorXd wrong(5), next;
  Eigen::Matrix<double, 1, 1> u(0.0);
  CHECK_THROWS_WITH(dynamic.step(wrong, u, next), Contains("x has size 5"));
  CHECK(CartPole<>().dt() == Approx(0.01).epsilon(1e-15));
}

TEST_CASE("CartPole: analytic Jacobians and VJP match finite differences",
          "[sim][cartpole][jacobian]") {
  check_random_jacobians(CartPole<double, 1>(), 11);
  check_random_jacobians(CartPole<double, 2>(), 12);
  check_random_jacobians(CartPole<double, 4>(), 13);
  check_random_jacobians(CartPole<double, Eigen::Dynamic>(3), 14);
  sbptt::CartPoleOptions other;
  other.horizon = 2.0;
  other.steps = 37;
  other.pole_mass = 0.3;
  other.half_length = 0.8;
  other.gravity = 3.7;
  check_random_jacobians(CartPole<double, 2>(other), 15);
}

TEST_CASE("CartPole: VJP with a null pointer skips that product only", "[sim][cartpole]") {
  const CartPole<double, 3> sim;
  sbptt::Rng rng(3);
  const auto x = random_state(sim, rng);
  CartPole<double, 3>::Control u(0.7), lu_both, lu_only;
  CartPole<double, 3>::State lambda = random_state(sim, rng), lx_both, lx_only;
  sim.vjp(x, u, lambda, &lx_both, &lu_both);
  sim.vjp(x, u, lambda, &lx_only, nullptr);
  sim.vjp(x, u, lambda, nullptr, &lu_only);
  CHECK(lx_both == lx_only);
  CHECK(lu_both == lu_only);
}

TEST_CASE("CartPole: Taylor remainder shrinks as O(h^2)", "[sim][cartpole][jacobian]") {
  check_taylor_ratios(CartPole<double, 4>(), 21);
}

TEST_CASE("CartPole: upright loss gradient matches finite differences", "[sim][cartpole]") {
  const CartPole<double, 4> sim;
  const auto objective = sbptt::cartpole_objective<double, 4>();
  CHECK(objective.timing == sbptt::LossTiming::Final);
  CHECK(objective.control_weight == 0.0);
  sbptt::Rng rng(5);
  for (int sample = 0; sample < 5; ++sample) {
    const auto x = random_state(sim, rng);
    CartPole<double, 4>::State grad;
    objective.state_loss(x, &grad);
    auto loss = [&](const sbptt::Vector<double>& xv, sbptt::Vector<double>& out) {
      out.resize(1);
      out(0) = objective.state_loss(CartPole<double, 4>::State(xv), nullptr);
    };
    const sbptt::Matrix<double> fd =
        sbptt::finite_difference_jacobian<double>(loss, x, 1).transpose();
    CHECK(sbptt::relative_error<double>(grad, fd) <= 1e-8);
  }
  CartPole<double, 4>::State upright = CartPole<double, 4>::State::Zero();
  CHECK(objective.state_loss(upright, nullptr) == 0.0);
}

TEST_CASE("CartPole: paper §5 rollout values (100 steps, final loss)", "[sim][cartpole][paper]") {
  struct Row {
    std::vector<double> state;
    double zero_force, unit_force;
  };
  const std::vector<Row> rows = {
      {{0, 0, kPi + 0.1, 0}, 1.9978070214, 1.9961662561},
      {{0.5, -0.5, kPi + 0.3, 0.2, kPi - 0.4, -0.7}, 1.9445479154, 1.9191568073},
      {{0, 0, kPi + 0.1, 0, kPi - 0.1, 0, kPi + 0.2, 0.5, kPi - 0.2, -0.5},
       1.9861196309, 1.9742742488},
  };
  for (const auto& row : rows) {
    const Index poles = static_cast<Index>(row.state.size() - 2) / 2;
    const CartPole<double, Eigen::Dynamic> sim(poles);
    const auto objective = sbptt::cartpole_objective<double, Eigen::Dynamic>();
    const Eigen::VectorXd x0 = Eigen::Map<const Eigen::VectorXd>(
        row.state.data(), static_cast<Index>(row.state.size()));
    const double zero = rollout_objective(sim, objective, x0, [](Index) { return 0.0; }, 100);
    const double unit = rollout_objective(sim, objective, x0, [](Index) { return 1.0; }, 100);
    INFO("poles " << poles);
    CHECK(std::abs(zero - row.zero_force) <= 1e-9);
    CHECK(std::abs(unit - row.unit_force) <= 1e-9);
  }
  // The fixed-size instantiation gives the same number (one-pole row).
  const CartPole<double, 1> fixed;
  const double fixed_value =
      rollout_objective(fixed, sbptt::cartpole_objective<double, 1>(),
                        CartPole<double, 1>::State(0, 0, kPi + 0.1, 0),
                        [](Index) { return 1.0; }, fixed.steps());
  CHECK(std::abs(fixed_value - 1.9961662561) <= 1e-9);
}

TEST_CASE("CartPole: equilibria at rest", "[sim][cartpole][invariant]") {
  const CartPole<double, 3> sim;
  const CartPole<double, 3>::Control zero(0.0);
  SECTION("upright at rest stays exactly at rest (sin 0 = 0 exactly)") {
    for (const double cart : {0.0, 0.7, -3.0}) {
      CartPole<double, 3>::State x = CartPole<double, 3>::State::Zero();
      x(0) = cart;
      const CartPole<double, 3>::State start = x;
      for (int n = 0; n < 1000; ++n) sim.step(x, zero, x);
      CHECK(x == start);
    }
  }
  SECTION("hanging at rest stays at rest to round-off") {
    // θ = fl(π) is not π: sin(fl(π)) ≈ 1.2e-16, so the exact equilibrium is not representable.
    // It is a stable one, so the state must stay within a few ulps-worth of rest for good.
    for (const double cart : {0.0, 0.7, -3.0}) {
      CartPole<double, 3>::State x = CartPole<double, 3>::State::Zero();
      x(0) = cart;
      for (Index i = 0; i < 3; ++i) x(2 + 2 * i) = (i == 1 ? -kPi : kPi);
      const CartPole<double, 3>::State start = x;
      for (int n = 0; n < 1000; ++n) sim.step(x, zero, x);
      CHECK((x - start).cwiseAbs().maxCoeff() <= 1e-12);
    }
  }
}

TEST_CASE("CartPole: float rollout stays within 1e-4 of double", "[sim][cartpole][float]") {
  sbptt::Rng rng(7);
  const CartPole<double, 4> sim_d;
  const CartPole<float, 4> sim_f;
  const sbptt::Matrix<double> starts = sbptt::cartpole_initial_states(sim_d, rng, 8);
  for (Index j = 0; j < starts.cols(); ++j) {
    CartPole<double, 4>::State xd = starts.col(j);
    CartPole<float, 4>::State xf = xd.cast<float>();
    double worst_gap = 0;  // over every step of the horizon, not only the last
    for (Index n = 0; n < sim_d.steps(); ++n) {
      const double force = 3.0 * std::sin(0.1 * static_cast<double>(n));
      sim_d.step(xd, CartPole<double, 4>::Control(force), xd);
      sim_f.step(xf, CartPole<float, 4>::Control(static_cast<float>(force)), xf);
      worst_gap = std::max(worst_gap, (xd - xf.cast<double>()).cwiseAbs().maxCoeff());
    }
    CHECK(worst_gap <= 1e-4);
    CHECK(std::abs(sbptt::CartPoleUprightLoss<float, 4>()(xf, nullptr) -
                   sbptt::CartPoleUprightLoss<double, 4>()(xd, nullptr)) <= 1e-4);
  }
  // float Jacobians agree with double ones to float accuracy.
  const CartPole<double, 4>::State x = starts.col(0);
  CartPole<double, 4>::StateJacobian a_d;
  CartPole<double, 4>::ControlJacobian b_d;
  CartPole<float, 4>::StateJacobian a_f;
  CartPole<float, 4>::ControlJacobian b_f;
  sim_d.jacobians(x, CartPole<double, 4>::Control(0.5), a_d, b_d);
  sim_f.jacobians(x.cast<float>(), CartPole<float, 4>::Control(0.5f), a_f, b_f);
  CHECK((a_d - a_f.cast<double>()).cwiseAbs().maxCoeff() <= 1e-5);
  CHECK((b_d - b_f.cast<double>()).cwiseAbs().maxCoeff() <= 1e-5);
  const CartPole<double, 4>::State lambda = CartPole<double, 4>::State::Constant(0.3);
  CartPole<double, 4>::State lx_d;
  CartPole<double, 4>::Control lu_d;
  CartPole<float, 4>::State lx_f;
  CartPole<float, 4>::Control lu_f;
  sim_d.vjp(x, CartPole<double, 4>::Control(0.5), lambda, &lx_d, &lu_d);
  sim_f.vjp(x.cast<float>(), CartPole<float, 4>::Control(0.5f), lambda.cast<float>(), &lx_f,
            &lu_f);
  CHECK((lx_d - lx_f.cast<double>()).cwiseAbs().maxCoeff() <= 1e-5);
  CHECK(std::abs(lu_d(0) - static_cast<double>(lu_f(0))) <= 1e-5);
}

// To rounding, not bit for bit: the two are separate instantiations, and GCC may fuse a·b + c
// into one FMA in one and not in the other (-ffp-contract=fast, its default), depending on how
// each is unrolled and inlined: a build of this file once differed in one entry of Aᵀλ of one
// sample. A few units in the last place of the largest entry allow that and nothing else.
template <class A, class B>
bool equal_to_rounding(const A& dynamic, const B& fixed) {
  // PropagateNaN: a NaN on either side fails (Eigen's default maxCoeff may skip one).
  const double scale =
      std::max(1.0, Eigen::MatrixXd(fixed).cwiseAbs().maxCoeff<Eigen::PropagateNaN>());
  return dynamic.rows() == fixed.rows() && dynamic.cols() == fixed.cols() &&
         (Eigen::MatrixXd(dynamic) - Eigen::MatrixXd(fixed))
                 .cwiseAbs()
                 .maxCoeff<Eigen::PropagateNaN>() <=
             4 * std::numeric_limits<double>::epsilon() * scale;
}

TEST_CASE("CartPole: dynamic pole count equals the fixed one", "[sim][cartpole][dynamic]") {
  const CartPole<double, 3> fixed;
  const CartPole<double, Eigen::Dynamic> dynamic(3);
  CHECK(dynamic.state_dim() == 8);
  sbptt::Rng rng(9);
  for (int sample = 0; sample < 5; ++sample) {
    const CartPole<double, 3>::State x = random_state(fixed, rng);
    const CartPole<double, 3>::State lambda = random_state(fixed, rng);
    const Eigen::Matrix<double, 1, 1> u(rng.uniform(-5, 5));
    CartPole<double, 3>::State next_f, lx_f;
    Eigen::VectorXd next_d, lx_d;
    CartPole<double, 3>::StateJacobian a_f;
    CartPole<double, 3>::ControlJacobian b_f;
    Eigen::MatrixXd a_d;
    Eigen::VectorXd b_d;
    Eigen::Matrix<double, 1, 1> lu_f, lu_d;
    fixed.step(x, u, next_f);
    dynamic.step(x, u, next_d);
    fixed.jacobians(x, u, a_f, b_f);
    dynamic.jacobians(x, u, a_d, b_d);
    fixed.vjp(x, u, lambda, &lx_f, &lu_f);
    dynamic.vjp(x, u, lambda, &lx_d, &lu_d);
    CHECK(equal_to_rounding(next_d, next_f));
    CHECK(equal_to_rounding(a_d, a_f));
    CHECK(equal_to_rounding(b_d, b_f));
    CHECK(equal_to_rounding(lx_d, lx_f));
    CHECK(equal_to_rounding(lu_d, lu_f));
  }
}

TEST_CASE("CartPole: one const instance stepped from two threads matches a serial run",
          "[sim][cartpole][thread]") {
  const CartPole<double, 4> sim;
  sbptt::Rng rng(17);
  const sbptt::Matrix<double> starts = sbptt::cartpole_initial_states(sim, rng, 2);
  // Each worker runs a long rollout with the adjoint products interleaved, so any hidden
  // shared scratch state would corrupt one of the two results.
  auto work = [&sim](CartPole<double, 4>::State x, double phase, Eigen::VectorXd& out) {
    CartPole<double, 4>::State lambda = CartPole<double, 4>::State::Ones(), lx;
    CartPole<double, 4>::Control u, lu;
    double adjoint_sum = 0;
    for (int n = 0; n < 20000; ++n) {
      u(0) = 2.0 * std::sin(0.01 * n + phase);
      sim.vjp(x, u, lambda, &lx, &lu);
      adjoint_sum += lx.sum() + lu(0);
      sim.step(x, u, x);
      x(2) = std::remainder(x(2), 2 * kPi);  // keep the angles bounded over the long run
    }
    out.resize(x.size() + 1);
    out << x, adjoint_sum;
  };
  std::vector<Eigen::VectorXd> serial(2), parallel(2);
  work(starts.col(0), 0.0, serial[0]);
  work(starts.col(1), 1.0, serial[1]);
  std::thread first(work, CartPole<double, 4>::State(starts.col(0)), 0.0, std::ref(parallel[0]));
  std::thread second(work, CartPole<double, 4>::State(starts.col(1)), 1.0, std::ref(parallel[1]));
  first.join();
  second.join();
  CHECK(parallel[0] == serial[0]);
  CHECK(parallel[1] == serial[1]);
}

TEST_CASE("CartPole: initial states follow the paper's distribution", "[sim][cartpole][data]") {
  const CartPole<double, 2> sim;
  sbptt::Rng rng(42), same(42), other(43);
  const sbptt::Matrix<double> states = sbptt::cartpole_initial_states(sim, rng, 4000);
  REQUIRE(states.rows() == 6);
  REQUIRE(states.cols() == 4000);
  CHECK(states == sbptt::cartpole_initial_states(sim, same, 4000));
  CHECK(states != sbptt::cartpole_initial_states(sim, other, 4000));
  for (const Index row : {0, 1, 3, 5}) {
    CHECK(states.row(row).minCoeff() >= -1.0);
    CHECK(states.row(row).maxCoeff() < 1.0);
    CHECK(std::abs(states.row(row).mean()) < 0.05);
  }
  for (const Index row : {2, 4}) {
    CHECK(states.row(row).minCoeff() >= kPi - kPi / 6);
    CHECK(states.row(row).maxCoeff() < kPi + kPi / 6);
    CHECK(std::abs(states.row(row).mean() - kPi) < 0.03);
    // Spread of U[−π/6, π/6): the angles are not all the same draw.
    CHECK(states.row(row).maxCoeff() - states.row(row).minCoeff() > 0.9 * kPi / 3);
  }
  CHECK_THROWS_AS(sbptt::cartpole_initial_states(sim, rng, -1), sbptt::InvalidArgument);
}

namespace {

sbptt::CartPoleOptions physical_options() {
  sbptt::CartPoleOptions o;
  o.model = sbptt::CartPoleModel::Physical;
  return o;
}

/// ½ M_P ẋ² + Σ_i (m l cos θ_i ẋ θ̇_i + ⅔ m l² θ̇_i² + m g l cos θ_i): the physical model's
/// energy, written from the poles' geometry (independent of the simulator's equations).
template <class Sim>
double physical_energy(const Sim& sim, const typename Sim::State& x) {
  const auto& o = sim.options();
  const double m = o.pole_mass, l = o.half_length, g = o.gravity;
  const double total = o.total_mass + static_cast<double>(sim.poles() - 1) * m;
  double e = 0.5 * total * x(1) * x(1);
  for (Index i = 0; i < sim.poles(); ++i) {
    const double theta = x(2 + 2 * i), omega = x(3 + 2 * i);
    e += m * l * std::cos(theta) * x(1) * omega + 2.0 / 3.0 * m * l * l * omega * omega +
         m * g * l * std::cos(theta);
  }
  return e;
}

}  // namespace

TEST_CASE("CartPole physical model: Jacobians, VJP and Taylor remainder",
          "[sim][cartpole][jacobian][physical]") {
  check_random_jacobians(CartPole<double, 1>(physical_options()), 61);
  check_random_jacobians(CartPole<double, 3>(physical_options()), 62);
  check_random_jacobians(CartPole<double, Eigen::Dynamic>(4, physical_options()), 63);
  check_taylor_ratios(CartPole<double, 4>(physical_options()), 64);
}

TEST_CASE("CartPole physical model: one pole is the reference; more poles feel each other",
          "[sim][cartpole][physical]") {
  sbptt::Rng rng(65);
  const CartPole<double, 1> reference, physical(physical_options());
  for (int sample = 0; sample < 20; ++sample) {
    auto a = random_state(reference, rng);
    auto b = a;
    const CartPole<double, 1>::Control u(rng.uniform(-5, 5));
    for (int n = 0; n < 100; ++n) {
      reference.step(a, u, a);
      physical.step(b, u, b);
    }
    CHECK((a - b).norm() <= 1e-12 * (1 + a.norm()));
  }
  // Two poles: moving pole 2 changes pole 1's acceleration in the physical model only.
  const CartPole<double, 2> ref2, phys2(physical_options());
  CartPole<double, 2>::State x(0, 0, kPi + 0.3, 0.5, kPi - 0.2, -1.0), y = x;
  y(4) += 0.4;
  const CartPole<double, 2>::Control u(1.0);
  CartPole<double, 2>::State xr, yr, xp, yp;
  ref2.step(x, u, xr);
  ref2.step(y, u, yr);
  phys2.step(x, u, xp);
  phys2.step(y, u, yp);
  CHECK(xr(3) == yr(3));
  CHECK(std::abs(xp(3) - yp(3)) > 1e-6);
}

TEST_CASE("CartPole physical model conserves energy as dt -> 0 (first-order drift)",
          "[sim][cartpole][physical][invariant]") {
  sbptt::Rng rng(66);
  for (int sample = 0; sample < 5; ++sample) {
    double drift[2] = {0, 0};
    CartPole<double, 3>::State x0;
    for (int level = 0; level < 2; ++level) {
      auto options = physical_options();
      options.steps = level == 0 ? 1000 : 10000;  // T = 1
      const CartPole<double, 3> sim(options);
      if (level == 0) x0 = random_state(sim, rng);
      auto x = x0;
      const double e0 = physical_energy(sim, x0);
      const CartPole<double, 3>::Control zero(0.0);
      for (Index n = 0; n < options.steps; ++n) {
        sim.step(x, zero, x);
        drift[level] = std::max(drift[level], std::abs(physical_energy(sim, x) - e0));
      }
    }
    INFO("sample " << sample << ": max energy drift " << drift[0] << " (dt = 1e-3), "
                   << drift[1] << " (dt = 1e-4)");
    CHECK(drift[1] < 1e-2);  // energies here are O(1): |ẋ| ≤ 3, |θ̇| ≤ 6
    CHECK(drift[0] / drift[1] > 5);
    CHECK(drift[0] / drift[1] < 20);
  }
}

TEST_CASE("CartPole physical model rejects a cart without mass", "[sim][cartpole][physical]") {
  auto options = physical_options();
  options.pole_mass = 1.25;  // fine for the reference model (< 4/3 M), not for a cart
  CHECK_NOTHROW(CartPole<>([] {
    sbptt::CartPoleOptions reference;
    reference.pole_mass = 1.25;
    return reference;
  }()));
  CHECK_THROWS_WITH(CartPole<>(options),
                    Catch::Matchers::Contains("pole_mass = 1.25 with the physical model"));
}
