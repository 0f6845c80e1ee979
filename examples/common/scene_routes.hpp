#pragma once
// The cart pole and guidance built three ways, for bench to price them side by side:
//   Analytic    the shipped simulator with its hand-written Jacobians and VJP;
//   Automatic   AutoDiffSimulator over a templated step (the cart pole's equations of
//               cartpole_equations.hpp; guidance's own step re-instantiated in dual numbers);
//   Integrated  Integrated<…> over continuous dynamics with automatic f-Jacobians (the cart
//               pole's accelerations with SemiImplicitEuler; guidance's f with ExplicitEuler).
// Every route reproduces the shipped step (tests/test_sim_integrators.cpp,
// tests/test_sim_autodiff_crosscheck.cpp).
#include "cartpole_equations.hpp"
#include "reinstantiated.hpp"
#include "sbptt/sim/autodiff.hpp"
#include "sbptt/sim/cartpole.hpp"
#include "sbptt/sim/guidance_by_repulsion.hpp"
#include "sbptt/sim/integrators.hpp"

namespace sbptt::examples {

enum class Route { Analytic, Automatic, Integrated };

template <class S, int Poles, Route R>
auto cartpole_route() {
  if constexpr (R == Route::Analytic) {
    return CartPole<S, Poles>();
  } else if constexpr (R == Route::Automatic) {
    return AutoDiffSimulator<CartPoleEquations<Poles>, S>();
  } else {
    return Integrated<CartPoleEquations<Poles>, SemiImplicitEuler, S>({}, S(0.01));
  }
}

template <class T>
using Guidance24 = GuidanceByRepulsion<T, 2, 4>;

/// Guidance's right-hand side f = (v, p̈) recovered from its explicit Euler step,
/// f = (P(x, u) − x) / dt: its accelerations are private to the shipped simulator, and
/// ExplicitEuler over this f is that simulator's map again.
template <class S>
struct GuidanceRate {
  static constexpr int kStateSize = 24, kControlSize = 4;
  Reinstantiated<Guidance24, S> scene{GuidanceOptions{}};
  double dt = GuidanceOptions{}.horizon / static_cast<double>(GuidanceOptions{}.steps);

  template <class T>
  void derivative(const ColumnOf<T, 24>& x, const ColumnOf<T, 4>& u, ColumnOf<T, 24>& f) const {
    ColumnOf<T, 24> next;
    scene.step(x, u, next);
    f = (next - x) / constant<T>(dt);
  }
};

template <class S, Route R>
auto guidance_route() {
  if constexpr (R == Route::Analytic) {
    return Guidance24<S>();
  } else if constexpr (R == Route::Automatic) {
    return AutoDiffSimulator<Reinstantiated<Guidance24, S>, S>(
        Reinstantiated<Guidance24, S>(GuidanceOptions{}));
  } else {
    const GuidanceRate<S> rate;
    return Integrated<GuidanceRate<S>, ExplicitEuler, S>(rate, static_cast<S>(rate.dt));
  }
}

}  // namespace sbptt::examples
