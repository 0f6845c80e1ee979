// The n-link pendulum on a cart against independent truths: the geometry of its links (energy
// and momentum from the link positions alone), the physical one-pole cart pole, conservation of
// energy and momentum without force and friction (drift shrinking at the integrator's order),
// and finite differences of the step.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "sbptt/core/finite_difference.hpp"
#include "sbptt/core/rng.hpp"
#include "sbptt/sim/cart_chain.hpp"
#include "sbptt/sim/cartpole.hpp"

using namespace sbptt;

namespace {

template <int Links>
using State = typename CartChainModel<Links>::template State<double>;

template <int Links>
State<Links> random_state(Rng& rng, double angle_spread = 3.0, double rate_spread = 2.0) {
  State<Links> x;
  x(0) = rng.uniform(-1, 1);
  x(1) = rng.uniform(-1, 1);
  for (int k = 0; k < Links; ++k) {
    x(2 + 2 * k) = rng.uniform(-angle_spread, angle_spread);
    x(3 + 2 * k) = rng.uniform(-rate_spread, rate_spread);
  }
  return x;
}

/// Positions of the cart (index 0, y = 0) and of every link's centre, from the file comment's
/// geometry only: q = (x, θ_1, …, θ_n), uniform rods of length L hinged end to end.
template <int Links>
std::vector<Eigen::Vector2d> centres(const Eigen::Matrix<double, Links + 1, 1>& q, double length) {
  std::vector<Eigen::Vector2d> p{{q(0), 0.0}};
  Eigen::Vector2d joint(q(0), 0.0);
  for (int k = 0; k < Links; ++k) {
    const Eigen::Vector2d along(std::sin(q(k + 1)), std::cos(q(k + 1)));
    p.emplace_back(joint + 0.5 * length * along);
    joint += length * along;
  }
  return p;
}

/// Energy and horizontal momentum from the geometry: velocities are central differences of the
/// positions along q̇ (exact to O(ε²) for these smooth maps), no mass matrix involved.
template <int Links>
std::pair<double, double> geometric_energy_momentum(const State<Links>& x,
                                                    const CartChainOptions& o) {
  Eigen::Matrix<double, Links + 1, 1> q, v;
  for (int i = 0; i <= Links; ++i) q(i) = x(2 * i), v(i) = x(2 * i + 1);
  const double h = 1e-6;
  const auto ahead = centres<Links>(q + h * v, o.link_length);
  const auto behind = centres<Links>(q - h * v, o.link_length);
  const auto here = centres<Links>(q, o.link_length);
  const double inertia = o.link_mass * o.link_length * o.link_length / 12;
  const double cart_speed = (ahead[0].x() - behind[0].x()) / (2 * h);
  double energy = 0.5 * o.cart_mass * cart_speed * cart_speed;
  double momentum = o.cart_mass * cart_speed;
  for (int k = 1; k <= Links; ++k) {
    const Eigen::Vector2d velocity = (ahead[static_cast<std::size_t>(k)] -
                                      behind[static_cast<std::size_t>(k)]) / (2 * h);
    energy += 0.5 * o.link_mass * velocity.squaredNorm() + 0.5 * inertia * v(k) * v(k) +
              o.link_mass * o.gravity * here[static_cast<std::size_t>(k)].y();
    momentum += o.link_mass * velocity.x();
  }
  return {energy, momentum};
}

/// Largest |E(t) − E(0)| over `seconds` of free motion (F = 0) from x0.
template <int Links, class Method>
double energy_drift(const State<Links>& x0, double dt, double seconds, double* momentum_drift) {
  const CartChain<double, Links, Method> sim(CartChainModel<Links>{}, dt);
  const auto& model = sim.model();
  State<Links> x = x0, next;
  const Eigen::Matrix<double, 1, 1> force = Eigen::Matrix<double, 1, 1>::Zero();
  const double e0 = model.energy(x), p0 = model.horizontal_momentum(x);
  double worst = 0, worst_p = 0;
  const auto steps = static_cast<long>(std::lround(seconds / dt));
  for (long n = 0; n < steps; ++n) {
    sim.step(x, force, next);
    x = next;
    worst = std::max(worst, std::abs(model.energy(x) - e0));
    worst_p = std::max(worst_p, std::abs(model.horizontal_momentum(x) - p0));
  }
  if (momentum_drift) *momentum_drift = worst_p;
  return worst;
}

}  // namespace

TEMPLATE_TEST_CASE_SIG("cart chain: energy and momentum equal those of the link geometry",
                       "[sim][chain]", ((int Links), Links), 1, 2, 3) {
  Rng rng(11);
  CartChainOptions options;
  options.link_mass = 0.3;  // not the default, so that the masses are exercised
  options.cart_mass = 0.7;
  options.link_length = 0.8;
  const CartChainModel<Links> model(options);
  for (int trial = 0; trial < 20; ++trial) {
    const State<Links> x = random_state<Links>(rng);
    const auto [energy, momentum] = geometric_energy_momentum<Links>(x, options);
    CHECK(model.energy(x) == Approx(energy).epsilon(1e-8));
    CHECK(model.horizontal_momentum(x) == Approx(momentum).epsilon(1e-8).margin(1e-9));
    const auto mass = model.mass_matrix(x);
    CHECK((mass - mass.transpose()).norm() == 0.0);
    CHECK(mass.ldlt().isPositive());
  }
}

TEST_CASE("cart chain: one link is the physical one-pole cart pole", "[sim][chain]") {
  CartPoleOptions pole;
  pole.model = CartPoleModel::Physical;  // cart 1.0 + pole 0.1, half-length 0.5, dt 0.01
  const CartPole<double, 1> cartpole(pole);
  const CartChain<double, 1> chain(CartChainModel<1>{}, 0.01);
  Rng rng(5);
  for (int trial = 0; trial < 20; ++trial) {
    const State<1> x = random_state<1>(rng);
    Eigen::Matrix<double, 1, 1> force;
    force(0) = rng.uniform(-5, 5);
    State<1> expected, actual;
    cartpole.step(x, force, expected);
    chain.step(x, force, actual);
    CHECK((actual - expected).norm() <= 1e-13 * (1 + expected.norm()));
  }
}

TEMPLATE_TEST_CASE_SIG("cart chain: frictionless and unforced, energy drift shrinks at the "
                       "integrator's order",
                       "[sim][chain]", ((int Links), Links), 1, 2, 3) {
  // A swinging start well away from rest (the chain hangs at ±40° and spins), 2 s.
  Rng rng(3);
  State<Links> x0 = random_state<Links>(rng, 0.7, 1.5);
  for (int k = 0; k < Links; ++k) x0(2 + 2 * k) += 3.14159;
  const double seconds = 2.0;

  SECTION("RungeKutta4: order 4 (its energy error here falls 30-fold per halving)") {
    double previous = 0;
    for (double dt : {0.02, 0.01, 0.005}) {
      double momentum = 0;
      const double drift = energy_drift<Links, RungeKutta4>(x0, dt, seconds, &momentum);
      INFO("dt " << dt << ": energy drift " << drift << ", momentum drift " << momentum);
      CHECK(drift < 1e-6);
      CHECK(momentum < 1e-6);
      if (previous > 0) CHECK(previous / drift > 0.7 * 16);  // at least order 4
      previous = drift;
    }
  }
  SECTION("SemiImplicitEuler (the cart pole's): order 1, bounded over a long run") {
    double previous = 0;
    for (double dt : {0.002, 0.001, 0.0005}) {
      const double drift = energy_drift<Links, SemiImplicitEuler>(x0, dt, seconds, nullptr);
      INFO("dt " << dt << ": energy drift " << drift);
      CHECK(drift < 0.05);
      if (previous > 0) CHECK(previous / drift == Approx(2).epsilon(0.3));
      previous = drift;
    }
    // Ten times longer does not mean ten times the error: the error oscillates, it does not
    // accumulate.
    const double short_run = energy_drift<Links, SemiImplicitEuler>(x0, 0.001, seconds, nullptr);
    const double long_run =
        energy_drift<Links, SemiImplicitEuler>(x0, 0.001, 10 * seconds, nullptr);
    INFO("2 s: " << short_run << ", 20 s: " << long_run);
    CHECK(long_run < 3 * short_run);
  }
}

TEMPLATE_TEST_CASE_SIG("cart chain: Jacobians and VJP equal finite differences of the step",
                       "[sim][chain]", ((int Links), Links), 1, 2, 3) {
  Rng rng(17);
  const CartChain<double, Links> euler(CartChainModel<Links>{}, 0.01);
  const CartChain<double, Links, RungeKutta4> rk4(CartChainModel<Links>{}, 0.01);
  for (int trial = 0; trial < 5; ++trial) {
    const State<Links> x = random_state<Links>(rng);
    Eigen::Matrix<double, 1, 1> force;
    force(0) = rng.uniform(-5, 5);
    CHECK(check_jacobians(euler, x, force).worst() < 1e-6);
    CHECK(check_jacobians(rk4, x, force).worst() < 1e-6);
  }
}

TEST_CASE("cart chain: float steps and differentiates like double", "[sim][chain]") {
  const CartChain<float, 2> sim(CartChainModel<2>{}, 0.01f);
  Rng rng(23);
  const State<2> xd = random_state<2>(rng);
  const CartChain<float, 2>::State x = xd.cast<float>();
  CartChain<float, 2>::Control u;
  u(0) = 1.5f;
  CHECK(check_jacobians(sim, x, u).worst() < 2e-2f);
  const CartChain<double, 2> reference(CartChainModel<2>{}, 0.01);
  State<2> next_d;
  CartChain<float, 2>::State next_f;
  reference.step(xd, Eigen::Matrix<double, 1, 1>::Constant(1.5), next_d);
  sim.step(x, u, next_f);
  CHECK((next_f.cast<double>() - next_d).norm() < 1e-5 * (1 + next_d.norm()));
}

TEST_CASE("cart chain: bad constants are refused with the value and what was expected",
          "[sim][chain]") {
  CartChainOptions options;
  options.link_mass = -0.1;
  CHECK_THROWS_WITH(CartChainModel<2>(options),
                    Catch::Contains("link mass = -0.1") && Catch::Contains("expected"));
  options = {};
  options.link_length = std::nan("");
  CHECK_THROWS_WITH(CartChainModel<2>(options), Catch::Contains("link length = nan"));
}
