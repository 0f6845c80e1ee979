// AutoDiffSimulator: a scene written as a templated step gets Jacobians and a VJP that agree
// with finite differences of the step (fixed and dynamic sizes, double and float, a Lagrangian
// scene with a mass-matrix solve), and it trains through the engine like a hand-written one.
#include <catch2/catch.hpp>

#include "double_pendulum.hpp"
#include "sbptt/bptt/engine.hpp"
#include "sbptt/bptt/losses.hpp"
#include "sbptt/core/finite_difference.hpp"
#include "sbptt/core/rng.hpp"
#include "sbptt/sim/autodiff.hpp"
#include "sbptt/sim/linear.hpp"
#include "polynomial_policy.hpp"

using namespace sbptt;

namespace {

/// Two masses on a line joined by a spring, the first pushed by u, with cubic friction:
/// v_i' = v_i + dt (F_i − γ v_i³), p_i' = p_i + dt v_i'; F_1 = u + κ (p₂ − p₁), F_2 = −κ (p₂ − p₁).
/// State (p₁, v₁, p₂, v₂), control u.
struct CubicFriction {
  static constexpr int kStateSize = 4, kControlSize = 1;
  double dt = 0.1, friction = 0.5, stiffness = 2.0;
  template <class T>
  void step(const ColumnOf<T, 4>& x, const ColumnOf<T, 1>& u, ColumnOf<T, 4>& next) const {
    const T h = constant<T>(dt), gamma = constant<T>(friction);
    const T spring = constant<T>(stiffness) * (x(2) - x(0));
    next(1) = x(1) + h * (u(0) + spring - gamma * x(1) * x(1) * x(1));
    next(3) = x(3) + h * (-spring - gamma * x(3) * x(3) * x(3));
    next(0) = x(0) + h * next(1);
    next(2) = x(2) + h * next(3);
  }
};

/// A chain of `links` coupled oscillators with dynamic sizes: x'_i = x_i + dt sin(x_{i+1}) u_0 …
struct DynamicChain {
  static constexpr int kStateSize = Eigen::Dynamic, kControlSize = Eigen::Dynamic;
  Index links = 5;
  [[nodiscard]] Index state_dim() const { return links; }
  [[nodiscard]] Index control_dim() const { return 2; }
  template <class T>
  void step(const ColumnOf<T, Eigen::Dynamic>& x, const ColumnOf<T, Eigen::Dynamic>& u,
            ColumnOf<T, Eigen::Dynamic>& next) const {
    using std::sin, std::exp;
    for (Index i = 0; i < links; ++i) {
      const T right = x((i + 1) % links);
      next(i) = x(i) + T(0.1) * sin(right) * u(0) + T(0.05) * exp(-x(i) * x(i)) * u(1);
    }
    next(0) = T(2.5);  // an output that depends on nothing: zero derivatives
  }
};

// x' = A x + B u written as a templated step: the automatic A and B are exactly A and B.
struct Affine {
  static constexpr int kStateSize = 3, kControlSize = 2;
  Eigen::Matrix3d a{{0.9, 0.2, 0.0}, {-0.1, 1.1, 0.3}, {0.0, 0.4, 0.8}};
  Eigen::Matrix<double, 3, 2> b{{0.5, 0.0}, {2.0, 1.0}, {-1.0, 0.25}};
  template <class T>
  void step(const ColumnOf<T, 3>& x, const ColumnOf<T, 2>& u, ColumnOf<T, 3>& next) const {
    next = a.template cast<T>() * x + b.template cast<T>() * u;
  }
};

// The scalar system x' = 0.9 x + 0.5 u, written once by hand (LinearSystem) and once as a
// templated step: the same loss and the same R gradient to round-off.
struct Scalar1 {
  static constexpr int kStateSize = 1, kControlSize = 1;
  template <class T>
  void step(const ColumnOf<T, 1>& x, const ColumnOf<T, 1>& u, ColumnOf<T, 1>& next) const {
    next(0) = T(0.9) * x(0) + T(0.5) * u(0);
  }
};

template <class Vec>
Vec random_vector(Rng& rng, Index size, double scale = 1.0) {
  Vec v(size);
  for (Index i = 0; i < size; ++i) v(i) = static_cast<typename Vec::Scalar>(scale * rng.normal());
  return v;
}

/// A step for double only: it cannot be called with dual numbers (compile_fail_autodiff_*
/// shows the message AutoDiffSimulator then gives).
struct DoubleOnlyStep {
  static constexpr int kStateSize = 4, kControlSize = 1;
  void step(const ColumnOf<double, 4>& x, const ColumnOf<double, 1>& /*u*/,
            ColumnOf<double, 4>& next) const {
    next = x;
  }
};

}  // namespace

static_assert(SimulatorWithJacobians<AutoDiffSimulator<CubicFriction>>);
static_assert(SimulatorWithJacobians<AutoDiffSimulator<CubicFriction, float>>);
static_assert(SimulatorWithJacobians<AutoDiffSimulator<DynamicChain>>);

static_assert(sbptt::detail::StepsInDualNumbers<CubicFriction, double>);
static_assert(sbptt::detail::StepsInDualNumbers<CubicFriction, float>);
static_assert(sbptt::detail::StepsInDualNumbers<DynamicChain, double>);
static_assert(!sbptt::detail::StepsInDualNumbers<DoubleOnlyStep, double>);

TEST_CASE("AutoDiffSimulator's Jacobians and VJP agree with finite differences of the step",
          "[sim][autodiff]") {
  Rng rng(11);
  const AutoDiffSimulator<CubicFriction> point;
  const AutoDiffSimulator<examples::DoublePendulum> pendulum;
  const AutoDiffSimulator<DynamicChain> chain;
  for (int trial = 0; trial < 20; ++trial) {
    INFO("trial " << trial);
    const auto p = check_jacobians(point, random_vector<Eigen::Vector4d>(rng, 4),
                                   random_vector<Eigen::Matrix<double, 1, 1>>(rng, 1));
    CHECK(p.has_jacobians);
    CHECK(p.worst() < 1e-8);
    const auto d = check_jacobians(pendulum, random_vector<Eigen::Vector4d>(rng, 4, 2.0),
                                   random_vector<Eigen::Matrix<double, 1, 1>>(rng, 1, 3.0));
    CHECK(d.worst() < 1e-8);
    const auto c = check_jacobians(chain, random_vector<Vector<double>>(rng, 5),
                                   random_vector<Vector<double>>(rng, 2));
    CHECK(c.worst() < 1e-8);
  }
}

TEST_CASE("AutoDiffSimulator with the closed-form Jacobians of a linear step", "[sim][autodiff]") {
  const AutoDiffSimulator<Affine> sim;
  Eigen::Matrix3d a;
  Eigen::Matrix<double, 3, 2> b;
  sim.jacobians(Eigen::Vector3d(0.3, -2.0, 1.0), Eigen::Vector2d(0.1, 4.0), a, b);
  CHECK(a == sim.model().a);
  CHECK(b == sim.model().b);
}

TEST_CASE("AutoDiffSimulator in float matches finite differences at float precision",
          "[sim][autodiff][float]") {
  const AutoDiffSimulator<CubicFriction, float> sim;
  Rng rng(3);
  for (int trial = 0; trial < 10; ++trial) {
    const auto check = check_jacobians(sim, random_vector<Eigen::Vector4f>(rng, 4),
                                       random_vector<Eigen::Matrix<float, 1, 1>>(rng, 1));
    CHECK(check.worst() < 2e-2f);
  }
}

TEST_CASE("AutoDiffSimulator rejects sizes that disagree", "[sim][autodiff]") {
  CHECK_THROWS_WITH(AutoDiffSimulator<DynamicChain>(DynamicChain{.links = 0}),
                    Catch::Contains("state_dim() = 0"));
  const AutoDiffSimulator<DynamicChain> chain;
  Vector<double> next;
  CHECK_THROWS_WITH(chain.step(Vector<double>::Zero(4), Vector<double>::Zero(2), next),
                    Catch::Contains("x has size 4"));
  // An adjoint of another size: Aᵀλ would be a product of mismatched sizes (an abort).
  Vector<double> lambda_x, lambda_u;
  CHECK_THROWS_WITH(chain.vjp(Vector<double>::Zero(5), Vector<double>::Zero(2),
                              Vector<double>::Ones(3), &lambda_x, &lambda_u),
                    Catch::Contains("AutoDiffSimulator: lambda has size 3") &&
                        Catch::Contains("state_dim() = 5"));
}

TEST_CASE("An automatic simulator gives the engine the gradient of its analytic twin",
          "[sim][autodiff][bptt]") {
  const AutoDiffSimulator<Scalar1> automatic;
  const LinearSystem<double, 1, 1> analytic = LinearSystem<double, 1, 1>::scalar(0.9, 0.5);
  sbptt::testing::PolynomialPolicy<double> policy({2, 1});
  policy.params() << 0.3, -0.6;
  using Loss = SquaredDistanceLoss<Eigen::Matrix<double, 1, 1>>;
  const Objective<Loss> objective{Loss{Eigen::Matrix<double, 1, 1>::Constant(0.2)}};
  Engine<AutoDiffSimulator<Scalar1>, decltype(policy), Loss> e1(automatic, policy, objective, 12);
  Engine<LinearSystem<double, 1, 1>, decltype(policy), Loss> e2(analytic, policy, objective, 12);
  Matrix<double> x0(1, 3);
  x0 << -1.0, 0.4, 1.2;
  const auto g1 = e1.regular_and_modified(x0), g2 = e2.regular_and_modified(x0);
  CHECK(g1.loss == Approx(g2.loss).epsilon(1e-14));
  CHECK(relative_error<double>(g1.regular, g2.regular) < 1e-13);
  CHECK(relative_error<double>(g1.modified, g2.modified) < 1e-13);
}
