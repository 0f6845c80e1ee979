#pragma once
// A user-defined simulator: a point mass on a line with friction, pushed by a force u.
//   p' = p + dt·v',  v' = v + dt·(u − γ v)        State (p, v), Control (u)
// Linear, so its Jacobians are exact: A = [[1, dt(1 − dt γ)], [0, 1 − dt γ]], B = [dt², dt].
#include <sbptt/sbptt.hpp>

struct PointMass {
  using Scalar = double;
  using State = Eigen::Vector2d;
  using Control = Eigen::Matrix<double, 1, 1>;
  using StateJacobian = Eigen::Matrix2d;
  using ControlJacobian = Eigen::Vector2d;
  double dt_ = 0.1, friction = 0.5;

  sbptt::Index state_dim() const { return 2; }
  sbptt::Index control_dim() const { return 1; }
  double dt() const { return dt_; }
  void jacobians(const State&, const Control&, StateJacobian& a, ControlJacobian& b) const {
    const double damp = 1 - dt_ * friction;
    a << 1, dt_ * damp, 0, damp;
    b << dt_ * dt_, dt_;
  }
  void step(const State& x, const Control& u, State& next) const {
    StateJacobian a;
    ControlJacobian b;
    jacobians(x, u, a, b);
    next = a * x + b * u;
  }
  void vjp(const State& x, const Control& u, const State& l, State* lx, Control* lu) const {
    StateJacobian a;
    ControlJacobian b;
    jacobians(x, u, a, b);
    if (lx) *lx = a.transpose() * l;
    if (lu) *lu = b.transpose() * l;
  }
};
