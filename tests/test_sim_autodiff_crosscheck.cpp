// Every shipped simulator's hand-written Jacobians and VJP against the automatic ones of its own
// step, instantiated in dual numbers (AutoDiffSimulator over Reinstantiated): ≤ 1e-12 relative
// in double at 100 random states each, for the cart pole (reference and physical models, 1 and
// 3 poles), guidance (reference and physical centre, both flocking signs) and the linear system.
//
// Schrödinger is not among them: its step works in std::complex<Scalar>, which the standard
// defines only for float, double and long double ([complex.numbers]/2), and its
// ConstantTridiagonalLu is complex too; a dual-number complex would be a second implementation,
// not the shipped step. Its derivatives are checked against finite differences and its exact
// unitarity in test_sim_schrodinger.cpp.
#include <catch2/catch.hpp>

#include "reinstantiated.hpp"
#include "sbptt/core/finite_difference.hpp"
#include "sbptt/core/rng.hpp"
#include "sbptt/sim/autodiff.hpp"
#include "sbptt/sim/cartpole.hpp"
#include "sbptt/sim/guidance_by_repulsion.hpp"
#include "sbptt/sim/linear.hpp"

using namespace sbptt;

namespace {

template <class T>
using CartPole1 = CartPole<T, 1>;
template <class T>
using CartPole3 = CartPole<T, 3>;
template <class T>
using Guidance24 = GuidanceByRepulsion<T, 2, 4>;
template <class T>
using Linear32 = LinearSystem<T, 3, 2>;

/// LinearSystem's step x' = A x + B u written as a templated step (its constructor checks dt
/// with std::isfinite, which a dual number does not have).
struct AffineStep {
  static constexpr int kStateSize = 3, kControlSize = 2;
  Eigen::Matrix3d a;
  Eigen::Matrix<double, 3, 2> b;
  template <class T>
  void step(const ColumnOf<T, 3>& x, const ColumnOf<T, 2>& u, ColumnOf<T, 3>& next) const {
    next = a.template cast<T>() * x + b.template cast<T>() * u;
  }
};

constexpr int kStates = 100;

/// Worst relative disagreement of A, B, Aᵀλ and Bᵀλ between `analytic` and the automatic
/// derivatives of the same step, over `kStates` states drawn by `draw(rng, x, u)`.
template <class Analytic, class Model, class Draw>
double worst_disagreement(const Analytic& analytic, const AutoDiffSimulator<Model>& automatic,
                          Draw draw) {
  Rng rng(17);
  typename Analytic::State x(analytic.state_dim()), lambda(analytic.state_dim()), lx1, lx2, n1,
      n2;
  typename Analytic::Control u(analytic.control_dim()), lu1, lu2;
  typename Analytic::StateJacobian a1, a2;
  typename Analytic::ControlJacobian b1, b2;
  double worst = 0;
  for (int trial = 0; trial < kStates; ++trial) {
    draw(rng, x, u);
    for (Index i = 0; i < lambda.size(); ++i) lambda(i) = rng.normal();
    analytic.step(x, u, n1);
    automatic.step(x, u, n2);
    REQUIRE(n1 == n2);  // the same step, so the same values
    analytic.jacobians(x, u, a1, b1);
    automatic.jacobians(x, u, a2, b2);
    analytic.vjp(x, u, lambda, &lx1, &lu1);
    automatic.vjp(x, u, lambda, &lx2, &lu2);
    worst = std::max({worst, relative_error<double>(a1, a2), relative_error<double>(b1, b2),
                      relative_error<double>(lx1, lx2), relative_error<double>(lu1, lu2)});
  }
  return worst;
}

template <class Sim>
void draw_cartpole(Rng& rng, typename Sim::State& x, typename Sim::Control& u) {
  for (Index i = 0; i < x.size(); ++i) x(i) = rng.uniform(-4.0, 4.0);
  u(0) = rng.uniform(-10.0, 10.0);
}

}  // namespace

TEST_CASE("Cart pole: analytic derivatives equal the automatic ones", "[sim][autodiff][cartpole]") {
  for (const auto model : {CartPoleModel::Reference, CartPoleModel::Physical}) {
    CartPoleOptions options;
    options.model = model;
    INFO("model " << static_cast<int>(model));
    const CartPole<double, 1> one(options);
    const AutoDiffSimulator<examples::Reinstantiated<CartPole1>> one_auto{
        examples::Reinstantiated<CartPole1>(options)};
    CHECK(worst_disagreement(one, one_auto, draw_cartpole<CartPole<double, 1>>) <= 1e-12);
    const CartPole<double, 3> three(options);
    const AutoDiffSimulator<examples::Reinstantiated<CartPole3>> three_auto{
        examples::Reinstantiated<CartPole3>(options)};
    CHECK(worst_disagreement(three, three_auto, draw_cartpole<CartPole<double, 3>>) <= 1e-12);
  }
}

TEST_CASE("Guidance: analytic derivatives equal the automatic ones", "[sim][autodiff][guidance]") {
  for (const auto center : {GuidanceCenter::Sum, GuidanceCenter::Centroid}) {
    for (const auto flocking : {FlockingSign::AsCoded, FlockingSign::AsIntended}) {
      GuidanceOptions options;
      options.physical = {center, flocking};
      INFO("centre " << static_cast<int>(center) << ", flocking " << static_cast<int>(flocking));
      const Guidance24<double> sim(options);
      const AutoDiffSimulator<examples::Reinstantiated<Guidance24>> automatic{
          examples::Reinstantiated<Guidance24>(options)};
      const auto draw = [](Rng& rng, Guidance24<double>::State& x, Guidance24<double>::Control& u) {
        for (Index i = 0; i < x.size(); ++i) x(i) = rng.uniform(-3.0, 3.0);
        for (Index i = 0; i < u.size(); ++i) u(i) = rng.uniform(-2.0, 2.0);
      };
      CHECK(worst_disagreement(sim, automatic, draw) <= 1e-12);
    }
  }
}

TEST_CASE("Linear system: analytic derivatives equal the automatic ones",
          "[sim][autodiff][linear]") {
  Eigen::Matrix3d a;
  a << 0.9, 0.2, 0.0, -0.1, 1.1, 0.3, 0.0, 0.4, 0.8;
  Eigen::Matrix<double, 3, 2> b;
  b << 0.5, 0.0, 2.0, 1.0, -1.0, 0.25;
  const Linear32<double> sim(a, b);
  const AutoDiffSimulator<AffineStep> automatic(AffineStep{a, b});
  const auto draw = [](Rng& rng, Linear32<double>::State& x, Linear32<double>::Control& u) {
    for (Index i = 0; i < x.size(); ++i) x(i) = rng.normal();
    for (Index i = 0; i < u.size(); ++i) u(i) = rng.normal();
  };
  CHECK(worst_disagreement(sim, automatic, draw) <= 1e-12);
}
