#pragma once
// The reference multi-pole cart pole (docs/simulators.md) written as its equations only, for the
// adapter and the integrators: `acceleration` for `Integrated` (any of the four methods), and
// `step`, its semi-implicit Euler step, for `AutoDiffSimulator`. With the paper's constants both
// reproduce `sbptt::CartPole`'s step (the tests check it); bench prices them against the
// hand-written derivatives, and accuracy compares the integrators at equal cost.
//
//   A_i = (F + m l θ̇_i² sin θ_i) / M,   θ̈_i = (g sin θ_i − cos θ_i A_i) / (l (4/3 − m cos²θ_i / M))
//   ẍ = (F + m l Σ_i (θ̇_i² sin θ_i − θ̈_i cos θ_i)) / M
//
// State (x, ẋ, θ_1, θ̇_1, …) interleaved, control F.
#include <cmath>

#include "sbptt/sim/autodiff.hpp"
#include "sbptt/sim/integrators.hpp"

namespace sbptt::examples {

template <int Poles>
struct CartPoleEquations {
  static constexpr int kStateSize = 2 + 2 * Poles, kControlSize = 1;
  static constexpr StateLayout kLayout = StateLayout::Interleaved;
  double gravity = 9.8, pole_mass = 0.1, total_mass = 1.1, half_length = 0.5, dt = 0.01;

  template <class T>
  void acceleration(const ColumnOf<T, kStateSize>& x, const ColumnOf<T, 1>& u,
                    ColumnOf<T, 1 + Poles>& a) const {
    using std::cos, std::sin;
    const T g = constant<T>(gravity), l = constant<T>(half_length);
    const T inv_mass = constant<T>(1.0 / total_mass), ratio = constant<T>(pole_mass / total_mass);
    const T ml_over_m = constant<T>(pole_mass * half_length / total_mass);
    T pole_sum(0);
    for (Index i = 0; i < Poles; ++i) {
      const T s = sin(x(2 + 2 * i)), c = cos(x(2 + 2 * i)), w2 = x(3 + 2 * i) * x(3 + 2 * i);
      const T push = inv_mass * u(0) + ml_over_m * w2 * s;
      a(1 + i) = (g * s - c * push) / (l * (constant<T>(4.0 / 3.0) - ratio * c * c));
      pole_sum += w2 * s - a(1 + i) * c;
    }
    a(0) = inv_mass * u(0) + ml_over_m * pole_sum;
  }

  template <class T>
  void step(const ColumnOf<T, kStateSize>& x, const ColumnOf<T, 1>& u,
            ColumnOf<T, kStateSize>& next) const {
    ColumnOf<T, 1 + Poles> a;
    acceleration(x, u, a);
    const T h = constant<T>(dt);
    for (Index i = 0; i < 1 + Poles; ++i) {
      next(2 * i + 1) = x(2 * i + 1) + h * a(i);
      next(2 * i) = x(2 * i) + h * next(2 * i + 1);
    }
  }
};

}  // namespace sbptt::examples
