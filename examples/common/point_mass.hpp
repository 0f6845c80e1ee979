#pragma once
// A user's scene: a point mass on a line with friction, pushed by a force u, written once as its
// equations, a step templated on the scalar. AutoDiffSimulator derives its Jacobians and VJP.
//   v' = v + dt·(u − γ v),  p' = p + dt·v'        State (p, v), Control (u)
#include <sbptt/sbptt.hpp>

struct PointMassEquations {
  static constexpr int kStateSize = 2, kControlSize = 1;
  double dt = 0.1, friction = 0.5;

  template <class T>
  void step(const sbptt::ColumnOf<T, 2>& x, const sbptt::ColumnOf<T, 1>& u,
            sbptt::ColumnOf<T, 2>& next) const {
    next(1) = x(1) + dt * (u(0) - friction * x(1));
    next(0) = x(0) + dt * next(1);
  }
};

using PointMass = sbptt::AutoDiffSimulator<PointMassEquations>;
