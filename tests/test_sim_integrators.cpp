// Integrated<Model, Method>: the discrete maps of explicit Euler, semi-implicit Euler, Heun and
// RK4 have Jacobians and VJPs that agree with finite differences and whose Taylor remainders
// fall as ε²; the observed orders on the harmonic oscillator's closed form are 1, 1, 2 and 4;
// the symplectic integrator's energy error stays bounded over 10⁴ steps of a pendulum;
// hand-written f- or a-Jacobians run at every stage.
#include <cmath>
#include <type_traits>

#include <catch2/catch.hpp>

#include "cartpole_equations.hpp"
#include "double_pendulum.hpp"
#include "sbptt/core/finite_difference.hpp"
#include "sbptt/core/rng.hpp"
#include "sbptt/sim/cartpole.hpp"
#include "sbptt/sim/integrators.hpp"

using namespace sbptt;

namespace {

/// Damped, driven pendulum q̈ = −ω² sin q − c q̇ + u, state (q, q̇) stacked.
struct Pendulum {
  static constexpr int kStateSize = 2, kControlSize = 1;
  double omega2 = 1.0, damping = 0.3;
  template <class T>
  void acceleration(const ColumnOf<T, 2>& x, const ColumnOf<T, 1>& u, ColumnOf<T, 1>& a) const {
    using std::sin;
    a(0) = -T(omega2) * sin(x(0)) - T(damping) * x(1) + u(0);
  }
};

/// A first-order model with a control on two channels (a forced Lotka–Volterra system),
/// with its Jacobians also written by hand, so both paths can be compared.
struct Predation {
  static constexpr int kStateSize = 2, kControlSize = 2;
  template <class T>
  void derivative(const ColumnOf<T, 2>& x, const ColumnOf<T, 2>& u, ColumnOf<T, 2>& f) const {
    f(0) = x(0) * (T(1.0) - x(1)) + u(0) * x(0);
    f(1) = x(1) * (x(0) - T(1.0)) + u(1);
  }
};
struct PredationAnalytic : Predation {
  void derivative_jacobians(const Eigen::Vector2d& x, const Eigen::Vector2d& u,
                            Eigen::Matrix2d& fx, Eigen::Matrix2d& fu) const {
    fx << 1.0 - x(1) + u(0), -x(0), x(1), x(0) - 1.0;
    fu << x(0), 0.0, 0.0, 1.0;
  }
};

/// The pendulum with its a-Jacobians by hand, templated on the scalar, counting its calls.
struct PendulumAnalytic : Pendulum {
  int* calls = nullptr;
  template <class T>
  void acceleration_jacobians(const ColumnOf<T, 2>& x, const ColumnOf<T, 1>& /*u*/,
                              Eigen::Matrix<T, 1, 2>& ax, Eigen::Matrix<T, 1, 1>& au) const {
    using std::cos;
    ++*calls;
    ax << -T(omega2) * cos(x(0)), -T(damping);
    au << T(1.0);
  }
};

/// The predation model's f-Jacobians by hand, counting their calls.
struct PredationCounted : PredationAnalytic {
  int* calls = nullptr;
  void derivative_jacobians(const Eigen::Vector2d& x, const Eigen::Vector2d& u,
                            Eigen::Matrix2d& fx, Eigen::Matrix2d& fu) const {
    ++*calls;
    PredationAnalytic::derivative_jacobians(x, u, fx, fu);
  }
};

// A Jacobian member is found by its name whatever its signature (a template, a final model),
// so one that cannot be called is refused (the compile_fail_integrated_* tests) instead of
// being replaced by automatic Jacobians without a word.
struct NonConstJacobians : Predation {
  void derivative_jacobians(const Eigen::Vector2d&, const Eigen::Vector2d&, Eigen::Matrix2d&,
                            Eigen::Matrix2d&) {}
};
struct FinalPredation final : PredationAnalytic {};
static_assert(!sbptt::detail::NamesDerivativeJacobians<Predation>);
static_assert(!sbptt::detail::NamesAccelerationJacobians<Pendulum>);
static_assert(sbptt::detail::NamesDerivativeJacobians<PredationAnalytic> &&
              sbptt::detail::HasDerivativeJacobians<PredationAnalytic, double>);
static_assert(sbptt::detail::NamesDerivativeJacobians<FinalPredation> &&
              sbptt::detail::HasDerivativeJacobians<FinalPredation, double>);
static_assert(sbptt::detail::NamesAccelerationJacobians<PendulumAnalytic> &&
              sbptt::detail::HasAccelerationJacobians<PendulumAnalytic, double>);
static_assert(sbptt::detail::NamesDerivativeJacobians<NonConstJacobians> &&
              !sbptt::detail::HasDerivativeJacobians<NonConstJacobians, double>);

/// x and the ε² slope of the remainder ‖P(x + εd, u + εe) − P(x, u) − ε(A d + B e)‖ and of its
/// adjoint twin |⟨λ, P(x + εd, u + εe) − P(x, u)⟩ − ε(⟨Aᵀλ, d⟩ + ⟨Bᵀλ, e⟩)|.
template <class Sim>
void check_taylor_slopes(const Sim& sim, const typename Sim::State& x,
                         const typename Sim::Control& u, Rng& rng) {
  using State = typename Sim::State;
  using Control = typename Sim::Control;
  State d(sim.state_dim()), lambda(sim.state_dim()), base, moved, lx;
  Control e(sim.control_dim()), lu;
  for (Index i = 0; i < d.size(); ++i) d(i) = rng.normal(), lambda(i) = rng.normal();
  for (Index i = 0; i < e.size(); ++i) e(i) = rng.normal();
  typename Sim::StateJacobian a;
  typename Sim::ControlJacobian b;
  sim.jacobians(x, u, a, b);
  sim.vjp(x, u, lambda, &lx, &lu);
  sim.step(x, u, base);
  const State linear = a * d + b * e;
  const double adjoint_linear = lx.dot(d) + lu.dot(e);
  double previous = 0, previous_adjoint = 0;
  for (int level = 0; level < 4; ++level) {
    const double eps = 1e-2 / std::pow(2.0, level);
    const State xe = x + eps * d;
    const Control ue = u + eps * e;
    sim.step(xe, ue, moved);
    const double remainder = (moved - base - eps * linear).norm();
    const double adjoint = std::abs(lambda.dot(moved - base) - eps * adjoint_linear);
    if (level > 0) {
      INFO("eps " << eps);
      CHECK(std::log2(previous / remainder) == Approx(2.0).margin(0.1));
      CHECK(std::log2(previous_adjoint / adjoint) == Approx(2.0).margin(0.1));
    }
    previous = remainder;
    previous_adjoint = adjoint;
  }
}

template <class Method>
void check_derivatives(Rng& rng) {
  const Integrated<Pendulum, Method> pendulum(Pendulum{}, 0.1);
  const Integrated<examples::DoublePendulum, Method> chaotic(examples::DoublePendulum{}, 0.01);
  for (int trial = 0; trial < 10; ++trial) {
    INFO("trial " << trial);
    const Eigen::Vector2d x(rng.uniform(-2, 2), rng.uniform(-2, 2));
    const Eigen::Matrix<double, 1, 1> u = Eigen::Matrix<double, 1, 1>::Constant(rng.normal());
    CHECK(check_jacobians(pendulum, x, u).worst() < 1e-8);
    check_taylor_slopes(pendulum, x, u, rng);
    const Eigen::Vector4d x4(rng.uniform(-3, 3), rng.uniform(-3, 3), rng.normal(), rng.normal());
    CHECK(check_jacobians(chaotic, x4, u).worst() < 1e-8);
    check_taylor_slopes(chaotic, x4, u, rng);
  }
  if constexpr (!std::is_same_v<Method, SemiImplicitEuler>) {
    const Integrated<Predation, Method> predation(Predation{}, 0.05);
    const Integrated<PredationAnalytic, Method> analytic(PredationAnalytic{}, 0.05);
    for (int trial = 0; trial < 10; ++trial) {
      const Eigen::Vector2d x(rng.uniform(0.2, 2), rng.uniform(0.2, 2));
      const Eigen::Vector2d u(rng.normal(), rng.normal());
      CHECK(check_jacobians(predation, x, u).worst() < 1e-8);
      check_taylor_slopes(predation, x, u, rng);
      // The hand-written f-Jacobians and the automatic ones give the same discrete map.
      Eigen::Matrix2d a1, a2, b1, b2;
      predation.jacobians(x, u, a1, b1);
      analytic.jacobians(x, u, a2, b2);
      CHECK(relative_error<double>(a1, a2) < 1e-14);
      CHECK(relative_error<double>(b1, b2) < 1e-14);
    }
  }
}

/// The state of the oscillator q̈ = −q at time t from (q₀, v₀): the closed form.
Eigen::Vector2d oscillator_exact(const Eigen::Vector2d& x0, double t) {
  return {x0(0) * std::cos(t) + x0(1) * std::sin(t), -x0(0) * std::sin(t) + x0(1) * std::cos(t)};
}

/// q̈ = −q + u, state (q, q̇).
struct HarmonicOscillator {
  static constexpr int kStateSize = 2, kControlSize = 1;
  template <class T>
  void acceleration(const ColumnOf<T, 2>& x, const ColumnOf<T, 1>& u, ColumnOf<T, 1>& a) const {
    a(0) = -x(0) + u(0);
  }
};

/// log₂ of the ratio of the errors at t = 2 with 20 and 40 steps: the observed order.
template <class Method>
double observed_order() {
  const Eigen::Vector2d x0(1.0, 0.5);
  const Eigen::Matrix<double, 1, 1> u = Eigen::Matrix<double, 1, 1>::Zero();
  const double horizon = 2.0;
  double errors[2];
  for (int level = 0; level < 2; ++level) {
    const int steps = 20 << level;
    const Integrated<HarmonicOscillator, Method> sim(HarmonicOscillator{}, horizon / steps);
    Eigen::Vector2d x = x0;
    for (int n = 0; n < steps; ++n) sim.step(x, u, x);
    errors[level] = (x - oscillator_exact(x0, horizon)).norm();
  }
  return std::log2(errors[0] / errors[1]);
}

/// max |E_n − E_0| of the frictionless pendulum q̈ = −sin q over steps [first, last).
template <class Method>
std::pair<double, double> energy_errors(int steps, int window) {
  const Integrated<Pendulum, Method> sim(Pendulum{.omega2 = 1.0, .damping = 0.0}, 0.05);
  const auto energy = [](const Eigen::Vector2d& x) { return 0.5 * x(1) * x(1) - std::cos(x(0)); };
  const Eigen::Matrix<double, 1, 1> u = Eigen::Matrix<double, 1, 1>::Zero();
  Eigen::Vector2d x(1.5, 0.0);
  const double e0 = energy(x);
  double early = 0, late = 0;
  for (int n = 1; n <= steps; ++n) {
    sim.step(x, u, x);
    const double error = std::abs(energy(x) - e0);
    if (n <= window) early = std::max(early, error);
    if (n > steps - window) late = std::max(late, error);
  }
  return {early, late};
}

}  // namespace

TEST_CASE("Each integrator's Jacobians and VJP are those of its discrete map",
          "[sim][integrators]") {
  Rng rng(5);
  SECTION("explicit Euler") { check_derivatives<ExplicitEuler>(rng); }
  SECTION("semi-implicit Euler") { check_derivatives<SemiImplicitEuler>(rng); }
  SECTION("Heun") { check_derivatives<Heun>(rng); }
  SECTION("RK4") { check_derivatives<RungeKutta4>(rng); }
}

TEST_CASE("A model's hand-written Jacobians run at every stage and give the automatic ones",
          "[sim][integrators]") {
  // One call per stage of the method: 1 for semi-implicit Euler, 4 for RK4, in `jacobians`
  // and again in `vjp`.
  int calls = 0;
  const Integrated<Pendulum, SemiImplicitEuler> automatic(Pendulum{}, 0.1);
  const Integrated<PendulumAnalytic, SemiImplicitEuler> analytic(PendulumAnalytic{{}, &calls}, 0.1);
  const Integrated<Pendulum, RungeKutta4> automatic4(Pendulum{}, 0.1);
  const Integrated<PendulumAnalytic, RungeKutta4> analytic4(PendulumAnalytic{{}, &calls}, 0.1);
  const Integrated<Predation, Heun> first_order(Predation{}, 0.05);
  const Integrated<PredationCounted, Heun> counted(PredationCounted{{}, &calls}, 0.05);
  const Eigen::Vector2d x(0.7, -0.4), lambda(0.3, -1.1);
  // The hand-written model's Jacobians against the automatic model's, and the calls they took.
  auto compare = [&](const auto& automatic_sim, const auto& analytic_sim, const auto& u,
                     int jacobian_calls) {
    using Control = std::decay_t<decltype(u)>;
    Eigen::Matrix2d a1, a2;
    Eigen::Matrix<double, 2, Control::RowsAtCompileTime> b1, b2;
    const int before = calls;
    automatic_sim.jacobians(x, u, a1, b1);
    analytic_sim.jacobians(x, u, a2, b2);
    CHECK(calls - before == jacobian_calls);
    CHECK(relative_error<double>(a2, a1) < 1e-14);
    CHECK(relative_error<double>(b2, b1) < 1e-14);
    Eigen::Vector2d lx;
    Control lu;
    analytic_sim.vjp(x, u, lambda, &lx, &lu);
    CHECK(calls - before == 2 * jacobian_calls);
  };
  compare(automatic, analytic, Eigen::Matrix<double, 1, 1>(0.2), 1);
  compare(automatic4, analytic4, Eigen::Matrix<double, 1, 1>(0.2), 4);
  compare(first_order, counted, Eigen::Vector2d(0.2, -0.5), 2);
}

TEST_CASE("Observed orders on the harmonic oscillator's closed form are 1, 1, 2 and 4",
          "[sim][integrators]") {
  CHECK(observed_order<ExplicitEuler>() == Approx(1.0).margin(0.15));
  CHECK(observed_order<SemiImplicitEuler>() == Approx(1.0).margin(0.15));
  CHECK(observed_order<Heun>() == Approx(2.0).margin(0.15));
  CHECK(observed_order<RungeKutta4>() == Approx(4.0).margin(0.15));
}

TEST_CASE("Semi-implicit Euler's energy error stays bounded over 10^4 pendulum steps",
          "[sim][integrators]") {
  // h = 0.05, 10⁴ steps (500 time units, ~80 periods): the symplectic map's energy error
  // oscillates at O(h) without drifting; explicit Euler's grows (the control experiment).
  const auto [early, late] = energy_errors<SemiImplicitEuler>(10000, 1000);
  INFO("semi-implicit: max |ΔE| first 1000 steps " << early << ", last 1000 " << late);
  CHECK(early < 0.05);
  CHECK(late < 1.1 * early);
  const auto [euler_early, euler_late] = energy_errors<ExplicitEuler>(10000, 1000);
  INFO("explicit Euler: " << euler_early << " then " << euler_late);
  CHECK(euler_late > 10 * late);
}

TEST_CASE("Integrated rejects a bad time step and an odd second-order state", "[sim][integrators]") {
  CHECK_THROWS_WITH((Integrated<Pendulum, Heun>(Pendulum{}, 0.0)), Catch::Contains("dt = 0"));
  CHECK_THROWS_WITH((Integrated<Pendulum, Heun>(Pendulum{}, std::nan(""))),
                    Catch::Contains("expected a finite time step"));
}

namespace {

/// ẋ_i = tanh(x_{i+1}) − x_i + u_{i mod k}, with sizes known at run time.
struct DynamicRing {
  static constexpr int kStateSize = Eigen::Dynamic, kControlSize = Eigen::Dynamic;
  Index n = 5, k = 2;
  [[nodiscard]] Index state_dim() const { return n; }
  [[nodiscard]] Index control_dim() const { return k; }
  template <class T>
  void derivative(const ColumnOf<T, Eigen::Dynamic>& x, const ColumnOf<T, Eigen::Dynamic>& u,
                  ColumnOf<T, Eigen::Dynamic>& rate) const {
    using std::tanh;
    for (Index i = 0; i < n; ++i) rate(i) = tanh(x((i + 1) % n)) - x(i) + u(i % k);
  }
};

}  // namespace

TEST_CASE("Integrated with dynamic sizes rejects inputs and adjoints of another size",
          "[sim][integrators]") {
  const Integrated<DynamicRing, RungeKutta4> sim({}, 0.1);
  Vector<double> next, lambda_x, lambda_u;
  CHECK_THROWS_WITH(sim.step(Vector<double>::Zero(4), Vector<double>::Zero(2), next),
                    Catch::Contains("x has size 4"));
  // An adjoint of another size: the reverse sweep over the stages read past it (an abort).
  CHECK_THROWS_WITH(sim.vjp(Vector<double>::Zero(5), Vector<double>::Zero(2),
                            Vector<double>::Ones(3), &lambda_x, &lambda_u),
                    Catch::Contains("Integrated: lambda has size 3") &&
                        Catch::Contains("state_dim() = 5"));
  const auto check = check_jacobians(sim, Vector<double>::Constant(5, 0.3),
                                     Vector<double>::Constant(2, -0.2));
  CHECK(check.worst() < 1e-8);
}

TEST_CASE("The cart pole's equations reproduce CartPole through SemiImplicitEuler and the adapter",
          "[sim][integrators][cartpole]") {
  // Interleaved layout, velocity first: the same map as the hand-written simulator, hence the
  // same values and derivatives up to round-off.
  const CartPole<double, 4> shipped;
  const examples::CartPoleEquations<4> equations;
  const Integrated<examples::CartPoleEquations<4>, SemiImplicitEuler> integrated(equations, 0.01);
  const AutoDiffSimulator<examples::CartPoleEquations<4>> adapter(equations);
  Rng rng(9);
  using State = CartPole<double, 4>::State;
  State x, lambda, n0, n1, n2, l0, l1, l2;
  Eigen::Matrix<double, 1, 1> u, m0, m1, m2;
  for (int trial = 0; trial < 100; ++trial) {
    for (Index i = 0; i < x.size(); ++i) x(i) = rng.uniform(-4, 4), lambda(i) = rng.normal();
    u(0) = rng.uniform(-10, 10);
    shipped.step(x, u, n0);
    integrated.step(x, u, n1);
    adapter.step(x, u, n2);
    CHECK(relative_error<double>(n1, n0) < 1e-14);
    CHECK(relative_error<double>(n2, n0) < 1e-14);
    shipped.vjp(x, u, lambda, &l0, &m0);
    integrated.vjp(x, u, lambda, &l1, &m1);
    adapter.vjp(x, u, lambda, &l2, &m2);
    CHECK(relative_error<double>(l1, l0) < 1e-12);
    CHECK(relative_error<double>(l2, l0) < 1e-12);
    CHECK(relative_error<double>(m1, m0) < 1e-12);
    CHECK(relative_error<double>(m2, m0) < 1e-12);
  }
}
