// Tests of guidance by repulsion (include/sbptt/sim/guidance_by_repulsion.hpp) against
// independent truth: central finite differences (also at and near coincident agents), the
// Taylor remainder, the paper's §4 rollout values, permutation symmetry, float-vs-double and
// fixed-vs-dynamic agreement, and concurrent use of one instance.
#include <catch2/catch.hpp>

#include <algorithm>
#include <array>

#include <cmath>
#include <functional>
#include <numbers>
#include <utility>
#include <thread>
#include <vector>

#include "sbptt/objectives/guidance.hpp"
#include "sbptt/bptt/engine.hpp"
#include "sbptt/bptt/objective.hpp"
#include "sbptt/core/concepts.hpp"
#include "sbptt/core/finite_difference.hpp"
#include "sbptt/core/rng.hpp"
#include "sbptt/nn/network.hpp"
#include "sbptt/sim/guidance_by_repulsion.hpp"

using sbptt::GuidanceByRepulsion;
using sbptt::Index;
constexpr int kDyn = Eigen::Dynamic;

namespace {

using Gbr = GuidanceByRepulsion<double, 2, 4>;

static_assert(sbptt::static_assert_simulator<Gbr>());
static_assert(sbptt::static_assert_simulator<GuidanceByRepulsion<float, 2, 4>>());
static_assert(sbptt::static_assert_simulator<GuidanceByRepulsion<double, 1, 1>>());
static_assert(sbptt::static_assert_simulator<GuidanceByRepulsion<double, kDyn, kDyn>>());
static_assert(sbptt::static_assert_simulator<GuidanceByRepulsion<double, 2, kDyn>>());
static_assert(Gbr::State::RowsAtCompileTime == 24);
static_assert(Gbr::Control::RowsAtCompileTime == 4);
static_assert(Gbr::ControlJacobian::ColsAtCompileTime == 4);
static_assert(GuidanceByRepulsion<double, 2, kDyn>::Control::RowsAtCompileTime == 4);

template <class Sim>
typename Sim::State random_state(const Sim& sim, sbptt::Rng& rng) {
  typename Sim::State x(sim.state_dim());
  for (Index a = 0; a < sim.agents(); ++a) {
    x(4 * a) = rng.uniform(-4, 4);
    x(4 * a + 1) = rng.uniform(-4, 4);
    x(4 * a + 2) = rng.uniform(-1, 1);
    x(4 * a + 3) = rng.uniform(-1, 1);
  }
  return x;
}

template <class Sim>
typename Sim::Control random_control(const Sim& sim, sbptt::Rng& rng) {
  typename Sim::Control u(sim.control_dim());
  for (Index k = 0; k < u.size(); ++k) u(k) = rng.uniform(-2, 2);
  return u;
}

/// Puts agent `moved` at distance `gap` from agent `anchor`, in a random direction.
template <class State>
void place_near(State& x, Index moved, Index anchor, double gap, sbptt::Rng& rng) {
  const double angle = rng.uniform(0, 2 * std::numbers::pi);
  x(4 * moved) = x(4 * anchor) + gap * std::cos(angle);
  x(4 * moved + 1) = x(4 * anchor + 1) + gap * std::sin(angle);
}

template <class Sim>
void check_state(const Sim& sim, const typename Sim::State& x, const typename Sim::Control& u,
                 double fd_step, const char* what) {
  const auto check = sbptt::check_jacobians(sim, x, u, fd_step);
  INFO(what << ": A " << check.state_jacobian_error << ", B " << check.control_jacobian_error
            << ", vjp " << check.vjp_error);
  CHECK(check.state_jacobian_error <= 1e-6);
  CHECK(check.control_jacobian_error <= 1e-6);
  CHECK(check.vjp_error <= 1e-6);
  CHECK(sbptt::vjp_jacobian_mismatch(sim, x, u) <= 1e-12);
}

template <class Sim>
void check_random_jacobians(const Sim& sim, std::uint64_t seed) {
  sbptt::Rng rng(seed);
  for (int sample = 0; sample < 20; ++sample) {
    check_state(sim, random_state(sim, rng), random_control(sim, rng),
                sbptt::default_fd_step<double>(), "random state");
  }
}

/// The objective formula of objective.hpp by a plain rollout (independent of the engine);
/// returns {state part, control part}.
template <class Sim, class Loss, class ControlAt>
std::pair<double, double> rollout_objective(const Sim& sim,
                                            const sbptt::Objective<Loss>& objective,
                                            typename Sim::State x, ControlAt control,
                                            Index steps) {
  double state_part = 0, control_sq = 0;
  for (Index n = 0; n < steps; ++n) {
    const typename Sim::Control u = control(n);
    control_sq += u.squaredNorm();
    sim.step(x, u, x);
    if (objective.timing == sbptt::LossTiming::Continuous || n + 1 == steps) {
      state_part += objective.step_weight * objective.state_loss(x, nullptr);
    }
  }
  return {state_part, objective.control_weight * control_sq /
                          static_cast<double>(steps * sim.control_dim())};
}

/// The paper's §4 sanity scene: drivers at (3.5, 0) and (0, −3.5), evaders at (1, 1) ±
/// (0.2, 0.2) in the four diagonal directions, all at rest.
Gbr::State sanity_state() {
  Gbr::State x = Gbr::State::Zero();
  x.segment<2>(0) << 3.5, 0.0;
  x.segment<2>(4) << 0.0, -3.5;
  const double offsets[4][2] = {{0.2, 0.2}, {0.2, -0.2}, {-0.2, 0.2}, {-0.2, -0.2}};
  for (Index e = 0; e < 4; ++e) {
    x.segment<2>(4 * (2 + e)) << 1.0 + offsets[e][0], 1.0 + offsets[e][1];
  }
  return x;
}

template <class Sim>
typename Sim::State rollout(const Sim& sim, typename Sim::State x,
                            const std::vector<typename Sim::Control>& controls) {
  for (const auto& u : controls) sim.step(x, u, x);
  return x;
}

/// ‖P(x + h δx, u + h δu) − P(x, u) − h (A δx + B δu)‖ at h over the same at h/2: about 4
/// when A and B are the derivatives (the remainder is O(h²)).
double taylor_ratio(const Gbr& sim, const Gbr::State& x, const Gbr::Control& u,
                    const Gbr::State& dx, const Gbr::Control& du, double h) {
  Gbr::StateJacobian a;
  Gbr::ControlJacobian b;
  sim.jacobians(x, u, a, b);
  Gbr::State base;
  sim.step(x, u, base);
  auto remainder = [&](double step) {
    Gbr::State moved;
    sim.step(x + step * dx, u + step * du, moved);
    return (moved - base - step * (a * dx + b * du)).norm();
  };
  return remainder(h) / remainder(h / 2);
}

}  // namespace

TEST_CASE("Guidance: constructor rejects bad options with a message naming the value",
          "[sim][guidance]") {
  using Catch::Matchers::Contains;
  sbptt::GuidanceOptions bad;
  bad.horizon = -4;
  CHECK_THROWS_WITH(Gbr(bad), Contains("horizon = -4"));
  bad = {};
  bad.steps = 0;
  CHECK_THROWS_WITH(Gbr(bad), Contains("steps = 0"));
  bad = {};
  bad.epsilon = 0;
  CHECK_THROWS_WITH(Gbr(bad), Contains("epsilon = 0"));
  bad = {};
  bad.flocking_offset = std::nan("");
  CHECK_THROWS_WITH(Gbr(bad), Contains("flocking_offset = nan"));
  bad = {};
  bad.repulsion_gain = INFINITY;
  CHECK_THROWS_WITH(Gbr(bad), Contains("inf"));
  bad = {};
  bad.physical.center = static_cast<sbptt::GuidanceCenter>(7);
  CHECK_THROWS_WITH(Gbr(bad), Contains("physical.center = 7"));
  CHECK_THROWS_WITH((GuidanceByRepulsion<double, kDyn, kDyn>(0, 3)), Contains("drivers = 0"));
  CHECK_THROWS_WITH((GuidanceByRepulsion<double, 2, 4>(2, 5)), Contains("evaders = 5"));
  CHECK_THROWS_WITH(sbptt::guidance_objective(Gbr(), -1.0), Contains("rc = -1"));

  const GuidanceByRepulsion<double, kDyn, kDyn> dynamic(2, 3);
  Eigen::VectorXd x = Eigen::VectorXd::Zero(20), wrong(19), next;
  Eigen::VectorXd u = Eigen::VectorXd::Zero(4);
  CHECK_THROWS_WITH(dynamic.step(wrong, u, next), Contains("x has size 19"));
  CHECK_THROWS_WITH(dynamic.step(x, Eigen::VectorXd::Zero(3), next), Contains("u has size 3"));
  CHECK(Gbr().dt() == Approx(1.0 / 15.0).epsilon(1e-15));
}

TEST_CASE("Guidance: analytic Jacobians and VJP match finite differences",
          "[sim][guidance][jacobian]") {
  check_random_jacobians(Gbr(), 31);
  check_random_jacobians(GuidanceByRepulsion<double, 1, 1>(), 32);
  check_random_jacobians(GuidanceByRepulsion<double, 3, 2>(), 33);
  check_random_jacobians(GuidanceByRepulsion<double, kDyn, kDyn>(3, 5), 34);
  sbptt::GuidanceOptions intended;
  intended.physical = {sbptt::GuidanceCenter::Centroid, sbptt::FlockingSign::AsIntended};
  check_random_jacobians(Gbr(intended), 35);
}

TEST_CASE("Guidance: Jacobians stay finite and correct when agents come close",
          "[sim][guidance][jacobian][singular]") {
  const Gbr sim;
  sbptt::Rng rng(41);
  // Pairs of each kind: driver–driver (0,1), evader–driver (2,0), evader–evader (3,4), (5,4).
  const Index pairs[4][2] = {{1, 0}, {2, 0}, {3, 4}, {5, 4}};
  SECTION("closer than epsilon = 0.1") {
    for (int sample = 0; sample < 6; ++sample) {
      Gbr::State x = random_state(sim, rng);
      for (const auto& pair : pairs) place_near(x, pair[0], pair[1], rng.uniform(0.001, 0.09), rng);
      // The kernels bend on the length scale ε + ‖r‖ ≈ 0.1 with gains up to 15/ε², so the
      // default step ∛ε·|x| ≈ 2e-5 leaves a truncation error near the tolerance; 1e-6
      // shrinks it 400-fold while round-off (~1e-16 / 1e-6) stays negligible.
      check_state(sim, x, random_control(sim, rng), 1e-6, "closer than epsilon");
    }
  }
  SECTION("1e-6 apart") {
    // ‖r‖ bends on the scale of the separation, so the finite-difference step must be well
    // below 1e-6 (the default ∛ε ≈ 6e-6 would straddle the kink); 1e-8 resolves it and still
    // keeps round-off (~1e-16 / 1e-8) far below the tolerance.
    for (int sample = 0; sample < 6; ++sample) {
      Gbr::State x = random_state(sim, rng);
      for (const auto& pair : pairs) place_near(x, pair[0], pair[1], 1e-6, rng);
      check_state(sim, x, random_control(sim, rng), 1e-8, "1e-6 apart");
    }
  }
  SECTION("exactly on the same spot") {
    for (int sample = 0; sample < 6; ++sample) {
      Gbr::State x = random_state(sim, rng);
      for (const auto& pair : pairs) place_near(x, pair[0], pair[1], 0.0, rng);
      const Gbr::Control u = random_control(sim, rng);
      Gbr::State next, lx;
      Gbr::Control lu;
      Gbr::StateJacobian a;
      Gbr::ControlJacobian b;
      sim.step(x, u, next);
      sim.jacobians(x, u, a, b);
      sim.vjp(x, u, Gbr::State::Ones(), &lx, &lu);
      CHECK(next.allFinite());
      CHECK(a.allFinite());
      CHECK(b.allFinite());
      CHECK(lx.allFinite());
      CHECK(lu.allFinite());
      // The pair kernels are C¹ at coincidence, so central differences straddling the kink
      // are off by O(h) only (≈ 2h/ε³ per unit gain); h ≈ 1e-9 balances that against
      // round-off O(1e-16 / h).
      check_state(sim, x, u, 1e-9, "coincident");
    }
  }
}

TEST_CASE("Guidance: Taylor remainder shrinks as O(h^2)", "[sim][guidance][jacobian]") {
  sbptt::GuidanceOptions intended;
  intended.physical.flocking = sbptt::FlockingSign::AsIntended;
  for (const Gbr& sim : {Gbr(), Gbr(intended)}) {
    sbptt::Rng rng(51);
    for (int sample = 0; sample < 20; ++sample) {
      Gbr::State x = random_state(sim, rng);
      place_near(x, 3, 2, 0.3, rng);  // evader pair in the flocking range
      const Gbr::Control u = random_control(sim, rng);
      const Gbr::State dx = random_state(sim, rng).normalized();
      const Gbr::Control du = random_control(sim, rng).normalized();
      for (const double h : {1e-2, 1e-3}) {
        const double ratio = taylor_ratio(sim, x, u, dx, du, h);
        INFO("sample " << sample << ", h = " << h << ", ratio = " << ratio);
        CHECK(ratio >= 3.5);
        CHECK(ratio <= 4.5);
      }
    }
  }
}

TEST_CASE("Guidance: Taylor remainder is O(h^2) with agents closer than epsilon",
          "[sim][guidance][jacobian][singular]") {
  // Every kind of pair 0.01–0.09 apart (ε = 0.1): the kernels bend on the scale ε + ‖r‖, so
  // the steps stay well below it.
  const Gbr sim;
  sbptt::Rng rng(52);
  const Index pairs[4][2] = {{1, 0}, {2, 0}, {3, 4}, {5, 4}};
  for (int sample = 0; sample < 20; ++sample) {
    Gbr::State x = random_state(sim, rng);
    for (const auto& pair : pairs) place_near(x, pair[0], pair[1], rng.uniform(0.01, 0.09), rng);
    const Gbr::Control u = random_control(sim, rng);
    const Gbr::State dx = random_state(sim, rng).normalized();
    const Gbr::Control du = random_control(sim, rng).normalized();
    for (const double h : {1e-3, 1e-4}) {
      const double ratio = taylor_ratio(sim, x, u, dx, du, h);
      INFO("sample " << sample << ", h = " << h << ", ratio = " << ratio);
      CHECK(ratio >= 3.5);
      CHECK(ratio <= 4.5);
    }
  }
}

TEST_CASE("Guidance: no flocking with one evader, no spreading with one driver",
          "[sim][guidance][invariant]") {
  // A term that cannot act must not change anything, whatever its gain.
  sbptt::GuidanceOptions strong;
  strong.flocking_gain = 50;
  strong.spreading_gain = 50;
  sbptt::Rng rng(53);
  const std::vector<Eigen::Vector4d> two_drivers(60, Eigen::Vector4d(-0.5, 0.3, 0.2, 0.1));
  const GuidanceByRepulsion<double, 2, 1> one_evader, one_evader_strong(strong);
  const auto x21 = random_state(one_evader, rng);
  CHECK(rollout(one_evader, x21, two_drivers) != rollout(one_evader, x21, {}));  // it moves
  const std::vector<Eigen::Vector2d> one_driver(60, Eigen::Vector2d(-0.5, 0.3));
  const GuidanceByRepulsion<double, 1, 3> one_driver_sim, one_driver_strong(strong);
  const auto x13 = random_state(one_driver_sim, rng);
  // With one driver the spreading gain is idle but flocking acts: only compare the spreading.
  sbptt::GuidanceOptions strong_spreading;
  strong_spreading.spreading_gain = 50;
  const GuidanceByRepulsion<double, 1, 3> one_driver_spreading(strong_spreading);
  CHECK(rollout(one_driver_sim, x13, one_driver) == rollout(one_driver_spreading, x13, one_driver));
  CHECK(rollout(one_driver_sim, x13, one_driver) != rollout(one_driver_strong, x13, one_driver));
  sbptt::GuidanceOptions strong_flocking;
  strong_flocking.flocking_gain = 50;
  const GuidanceByRepulsion<double, 2, 1> one_evader_flocking(strong_flocking);
  CHECK(rollout(one_evader, x21, two_drivers) == rollout(one_evader_flocking, x21, two_drivers));
  CHECK(rollout(one_evader, x21, two_drivers) != rollout(one_evader_strong, x21, two_drivers));
}

TEST_CASE("Guidance: evader loss and its gradient", "[sim][guidance]") {
  const Gbr sim;
  const auto objective = sbptt::guidance_objective(sim, 0.1);
  CHECK(objective.timing == sbptt::LossTiming::Continuous);
  CHECK(objective.step_weight == Approx(1.0 / 60.0));
  CHECK(objective.control_weight == 0.1);
  const auto fixed = sbptt::guidance_objective<double, 2, 4>(1.0, 30);
  CHECK(fixed.step_weight == Approx(1.0 / 30.0));
  sbptt::Rng rng(61);
  for (int sample = 0; sample < 5; ++sample) {
    const Gbr::State x = random_state(sim, rng);
    Gbr::State grad;
    const double value = objective.state_loss(x, &grad);
    double by_hand = 0;
    for (Index e = 2; e < 6; ++e) by_hand += x.segment<2>(4 * e).squaredNorm() / 8.0;
    CHECK(value == Approx(by_hand).epsilon(1e-14));
    auto loss = [&](const sbptt::Vector<double>& xv, sbptt::Vector<double>& out) {
      out.resize(1);
      out(0) = objective.state_loss(Gbr::State(xv), nullptr);
    };
    const sbptt::Matrix<double> fd =
        sbptt::finite_difference_jacobian<double>(loss, x, 1).transpose();
    CHECK(sbptt::relative_error<double>(grad, fd) <= 1e-8);
  }
  const GuidanceByRepulsion<double, kDyn, kDyn> dynamic(2, 4);
  const auto dyn_objective = sbptt::guidance_objective(dynamic, 0.1);
  const Eigen::VectorXd x = sanity_state();
  CHECK(dyn_objective.state_loss(x, nullptr) == objective.state_loss(sanity_state(), nullptr));
}

TEST_CASE("Guidance: paper §4 sanity values (60 steps, continuous loss)",
          "[sim][guidance][paper]") {
  const Gbr sim;
  const Gbr::State x0 = sanity_state();
  const auto zero = [](Index) { return Gbr::Control::Zero().eval(); };
  const auto constant = [](Index) { return Gbr::Control(-0.5, 0.3, -0.5, 0.3); };
  for (const double rc : {1.0, 0.1, 0.01}) {
    const auto [physics, reg] = rollout_objective(sim, sbptt::guidance_objective(sim, rc), x0,
                                                  zero, sim.steps());
    CHECK(std::abs(physics - 5.5665830665) <= 1e-9);
    CHECK(reg == 0.0);
  }
  const auto [physics1, reg1] =
      rollout_objective(sim, sbptt::guidance_objective(sim, 1.0), x0, constant, sim.steps());
  CHECK(std::abs(physics1 - 3.9309805839) <= 1e-9);
  CHECK(std::abs(reg1 - 0.17) <= 1e-12);
  CHECK(std::abs(physics1 + reg1 - 4.1009805839) <= 1e-9);
  const auto [physics01, reg01] =
      rollout_objective(sim, sbptt::guidance_objective(sim, 0.1), x0, constant, sim.steps());
  CHECK(std::abs(physics01 + reg01 - 3.9479805839) <= 1e-9);

  // The physical switches change the outcome (so they are wired), and with one evader the
  // sum and the centroid coincide exactly.
  sbptt::GuidanceOptions centroid;
  centroid.physical.center = sbptt::GuidanceCenter::Centroid;
  const double with_centroid =
      rollout_objective(Gbr(centroid), sbptt::guidance_objective(sim, 1.0), x0, constant, 60)
          .first;
  CHECK(std::abs(with_centroid - physics1) > 1e-3);
  const GuidanceByRepulsion<double, 2, 1> one_sum, one_centroid(centroid);
  GuidanceByRepulsion<double, 2, 1>::State x1 = x0.head<12>();
  const std::vector<Eigen::Vector4d> controls(60, Eigen::Vector4d(-0.5, 0.3, 0.2, 0.1));
  CHECK(rollout(one_sum, x1, controls) == rollout(one_centroid, x1, controls));
}

TEST_CASE("Guidance: the engine's batch loss gives the paper's §4 totals",
          "[sim][guidance][paper]") {
  // A controller whose output is its bias (zero weights) gives the constant control of the
  // sanity case; the engine's regulariser normalisation (rc · mean over steps and the
  // 4 control components) must reproduce 3.9309805839 + rc · 0.17.
  const Gbr sim;
  sbptt::Network<double> constant({sbptt::Dense{24, 4, sbptt::Activation::Identity}});
  constant.params().setZero();
  constant.params().tail<4>() << -0.5, 0.3, -0.5, 0.3;
  const Eigen::MatrixXd x0 = sanity_state();
  for (const auto& [rc, total] : {std::pair{1.0, 4.1009805839}, std::pair{0.1, 3.9479805839}}) {
    sbptt::Engine engine(sim, constant, sbptt::guidance_objective(sim, rc), sim.steps());
    CHECK(std::abs(engine.forward(x0) - total) <= 1e-9);
    CHECK(std::abs(engine.evaluate(x0) - total) <= 1e-9);
  }
}

TEST_CASE("Guidance: flocking sign as coded vs as intended", "[sim][guidance][invariant]") {
  // Two evaders 0.1 apart, the one driver far away on their perpendicular bisector (so it
  // pushes both alike). As coded they attract at this range; as intended they repel.
  using Sim = GuidanceByRepulsion<double, 1, 2>;
  Sim::State x = Sim::State::Zero();
  x.segment<2>(0) << 0.0, 50.0;
  x.segment<2>(4) << -0.05, 0.0;
  x.segment<2>(8) << 0.05, 0.0;
  sbptt::GuidanceOptions intended;
  intended.physical.flocking = sbptt::FlockingSign::AsIntended;
  const Sim::Control u = Sim::Control::Zero();
  auto gap_after_two_steps = [&](const Sim& sim) {
    Sim::State y = x;
    sim.step(y, u, y);
    sim.step(y, u, y);
    return (y.segment<2>(8) - y.segment<2>(4)).norm();
  };
  CHECK(gap_after_two_steps(Sim()) < 0.1);
  CHECK(gap_after_two_steps(Sim(intended)) > 0.1);
}

TEST_CASE("Guidance: rollouts are symmetric under permutation of the evaders, of the drivers, "
          "and of both", "[sim][guidance][invariant]") {
  const Gbr sim;
  sbptt::Rng rng(71);
  // new agent i is old agent order[i]; agents 0, 1 are the drivers, 2..5 the evaders.
  const std::array<Index, 6> evaders_only{0, 1, 4, 2, 5, 3}, drivers_only{1, 0, 2, 3, 4, 5},
      both{1, 0, 4, 2, 5, 3};
  for (const auto& order : {evaders_only, drivers_only, both}) {
    const bool drivers_swapped = order[0] == 1;
    for (int sample = 0; sample < 4; ++sample) {
      const Gbr::State x0 = sbptt::guidance_initial_states(sim, rng, 1).col(0);
      std::vector<Gbr::Control> controls, permuted_controls;
      for (Index n = 0; n < sim.steps(); ++n) {
        const Gbr::Control u = 0.5 * random_control(sim, rng);
        controls.push_back(u);
        permuted_controls.push_back(drivers_swapped ? Gbr::Control(u(2), u(3), u(0), u(1)) : u);
      }
      Gbr::State y0;
      auto old_agent = [&](Index i) { return 4 * order[static_cast<std::size_t>(i)]; };
      for (Index i = 0; i < 6; ++i) y0.segment<4>(4 * i) = x0.segment<4>(old_agent(i));
      const Gbr::State x_end = rollout(sim, x0, controls);
      const Gbr::State y_end = rollout(sim, y0, permuted_controls);
      for (Index i = 0; i < 6; ++i)
        CHECK((y_end.segment<4>(4 * i) - x_end.segment<4>(old_agent(i))).norm() <= 1e-12);
    }
  }
}

TEST_CASE("Guidance: float rollout stays within 1e-4 of double", "[sim][guidance][float]") {
  const Gbr sim_d;
  const GuidanceByRepulsion<float, 2, 4> sim_f;
  sbptt::Rng rng(81);
  const sbptt::Matrix<double> starts = sbptt::guidance_initial_states(sim_d, rng, 6);
  for (Index j = 0; j < starts.cols(); ++j) {
    Gbr::State xd = starts.col(j);
    GuidanceByRepulsion<float, 2, 4>::State xf = xd.cast<float>();
    double worst_gap = 0;  // over every step of the horizon, not only the last
    for (Index n = 0; n < sim_d.steps(); ++n) {
      const double t = static_cast<double>(n) * sim_d.dt();
      const Gbr::Control u(-0.5 + 0.2 * std::sin(t), 0.3, -0.4, 0.3 * std::cos(t));
      sim_d.step(xd, u, xd);
      sim_f.step(xf, u.cast<float>(), xf);
      worst_gap = std::max(worst_gap, (xd - xf.cast<double>()).cwiseAbs().maxCoeff());
    }
    CHECK(worst_gap <= 1e-4);
  }
  // float derivatives agree with double ones to float accuracy.
  using SimF = GuidanceByRepulsion<float, 2, 4>;
  const Gbr::State x = starts.col(0), lambda = Gbr::State::Constant(0.3);
  const Gbr::Control u(-0.5, 0.3, 0.2, -0.1);
  Gbr::StateJacobian a_d;
  Gbr::ControlJacobian b_d;
  SimF::StateJacobian a_f;
  SimF::ControlJacobian b_f;
  sim_d.jacobians(x, u, a_d, b_d);
  sim_f.jacobians(x.cast<float>(), u.cast<float>(), a_f, b_f);
  CHECK((a_d - a_f.cast<double>()).cwiseAbs().maxCoeff() <= 1e-5);
  CHECK((b_d - b_f.cast<double>()).cwiseAbs().maxCoeff() <= 1e-5);
  Gbr::State lx_d;
  Gbr::Control lu_d;
  SimF::State lx_f;
  SimF::Control lu_f;
  sim_d.vjp(x, u, lambda, &lx_d, &lu_d);
  sim_f.vjp(x.cast<float>(), u.cast<float>(), lambda.cast<float>(), &lx_f, &lu_f);
  CHECK((lx_d - lx_f.cast<double>()).cwiseAbs().maxCoeff() <= 1e-5);
  CHECK((lu_d - lu_f.cast<double>()).cwiseAbs().maxCoeff() <= 1e-5);
}

TEST_CASE("Guidance: dynamic agent counts equal the fixed ones", "[sim][guidance][dynamic]") {
  const Gbr fixed;
  const GuidanceByRepulsion<double, kDyn, kDyn> dynamic(2, 4);
  const GuidanceByRepulsion<double, 2, kDyn> mixed(2, 4);
  sbptt::Rng rng(91);
  for (int sample = 0; sample < 5; ++sample) {
    const Gbr::State x = random_state(fixed, rng), lambda = random_state(fixed, rng);
    const Gbr::Control u = random_control(fixed, rng);
    Gbr::State next_f, lx_f;
    Gbr::Control lu_f;
    Gbr::StateJacobian a_f;
    Gbr::ControlJacobian b_f;
    fixed.step(x, u, next_f);
    fixed.jacobians(x, u, a_f, b_f);
    fixed.vjp(x, u, lambda, &lx_f, &lu_f);
    Eigen::VectorXd next_d, lx_d, lu_d;
    Eigen::MatrixXd a_d, b_d;
    dynamic.step(x, u, next_d);
    dynamic.jacobians(x, u, a_d, b_d);
    dynamic.vjp(x, u, lambda, &lx_d, &lu_d);
    CHECK(next_d == next_f);
    CHECK(a_d == a_f);
    CHECK(b_d == b_f);
    CHECK(lx_d == lx_f);
    CHECK(lu_d == lu_f);
    GuidanceByRepulsion<double, 2, kDyn>::State next_m;
    mixed.step(x, u, next_m);
    CHECK(next_m == next_f);
  }
}

TEST_CASE("Guidance: one const instance stepped from two threads matches a serial run",
          "[sim][guidance][thread]") {
  const Gbr sim;
  sbptt::Rng rng(101);
  const sbptt::Matrix<double> starts = sbptt::guidance_initial_states(sim, rng, 2);
  auto work = [&sim](Gbr::State x, double phase, Eigen::VectorXd& out) {
    Gbr::State lx;
    Gbr::Control lu;
    double adjoint_sum = 0;
    for (int n = 0; n < 5000; ++n) {
      const double t = 0.01 * n + phase;
      const Gbr::Control u(-0.3 + 0.2 * std::sin(t), 0.2, -0.3, 0.2 * std::cos(t));
      sim.vjp(x, u, Gbr::State::Constant(0.1), &lx, &lu);
      adjoint_sum += lx.sum() + lu.sum();
      sim.step(x, u, x);
    }
    out.resize(x.size() + 1);
    out << x, adjoint_sum;
  };
  std::vector<Eigen::VectorXd> serial(2), parallel(2);
  work(starts.col(0), 0.0, serial[0]);
  work(starts.col(1), 1.0, serial[1]);
  std::thread first(work, Gbr::State(starts.col(0)), 0.0, std::ref(parallel[0]));
  std::thread second(work, Gbr::State(starts.col(1)), 1.0, std::ref(parallel[1]));
  first.join();
  second.join();
  CHECK(serial[0].allFinite());
  CHECK(parallel[0] == serial[0]);
  CHECK(parallel[1] == serial[1]);
}

TEST_CASE("Guidance: initial states follow the paper's distribution", "[sim][guidance][data]") {
  const GuidanceByRepulsion<double, 3, 5> sim;
  sbptt::Rng rng(42), same(42);
  const sbptt::Matrix<double> states = sbptt::guidance_initial_states(sim, rng, 2000);
  REQUIRE(states.rows() == 32);
  REQUIRE(states.cols() == 2000);
  CHECK(states == sbptt::guidance_initial_states(sim, same, 2000));
  double driver_radius_sum = 0;
  for (Index j = 0; j < states.cols(); ++j) {
    const Eigen::VectorXd x = states.col(j);
    for (Index a = 0; a < sim.agents(); ++a) {
      CHECK(x.segment<2>(4 * a + 2).isZero(0.0));  // at rest
    }
    for (Index d = 0; d < 3; ++d) {
      const double radius = x.segment<2>(4 * d).norm();
      driver_radius_sum += radius;
      CHECK((radius >= 3.0 - 1e-12 && radius <= 4.0 + 1e-12));
    }
    for (Index e = 3; e < 8; ++e) {
      const double radius = x.segment<2>(4 * e).norm();
      CHECK((radius >= 1.0 - std::sqrt(0.5) && radius <= 2.0 + std::sqrt(0.5)));
      for (Index f = 3; f < 8; ++f) {  // offsets from one centre lie in a unit square
        CHECK((x.segment<2>(4 * e) - x.segment<2>(4 * f)).cwiseAbs().maxCoeff() < 1.0);
      }
    }
  }
  CHECK(driver_radius_sum / 6000.0 == Approx(3.5).margin(0.02));  // uniform in r, not area
}
