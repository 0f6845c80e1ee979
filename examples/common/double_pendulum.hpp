#pragma once
// A planar double pendulum driven by a torque τ at the first joint, written once as its
// equations and differentiated automatically (the scene of docs/api.md; the tests check it
// against finite differences and its energy).
//
// Point masses m₁, m₂ on massless rods l₁, l₂; θᵢ absolute angles from the downward vertical.
// From the Lagrangian, with c = cos(θ₁ − θ₂), s = sin(θ₁ − θ₂):
//
//   M(θ) θ̈ = Q,  M = [(m₁+m₂) l₁²,  m₂ l₁ l₂ c;  m₂ l₁ l₂ c,  m₂ l₂²]
//   Q = (τ − m₂ l₁ l₂ s ω₂² − (m₁+m₂) g l₁ sin θ₁,  m₂ l₁ l₂ s ω₁² − m₂ g l₂ sin θ₂)
//   E = ½ ωᵀ M ω − (m₁+m₂) g l₁ cos θ₁ − m₂ g l₂ cos θ₂     (conserved when τ = 0)
//
// State (θ₁, θ₂, ω₁, ω₂) (stacked positions then velocities), control τ. `acceleration` is the
// continuous model for `Integrated`; `step` is one semi-implicit Euler step of it, the model for
// `AutoDiffSimulator`: ω' = ω + dt θ̈, θ' = θ + dt ω'.
#include <cmath>

#include <Eigen/Dense>

namespace sbptt::examples {

struct DoublePendulum {
  static constexpr int kStateSize = 4, kControlSize = 1;
  double m1 = 1, m2 = 1, l1 = 1, l2 = 1, g = 9.81, dt = 0.01;

  /// q̈ = M(θ)⁻¹ Q(θ, ω, τ), in any scalar (double, float or a dual number).
  template <class T>
  void acceleration(const Eigen::Matrix<T, 4, 1>& x, const Eigen::Matrix<T, 1, 1>& u,
                    Eigen::Matrix<T, 2, 1>& a) const {
    using std::cos, std::sin;
    const T c = cos(x(0) - x(1)), s = sin(x(0) - x(1)), k = T(m2 * l1 * l2);
    Eigen::Matrix<T, 2, 2> mass;
    mass << T((m1 + m2) * l1 * l1), k * c, k * c, T(m2 * l2 * l2);
    const Eigen::Matrix<T, 2, 1> forces(u(0) - k * s * x(3) * x(3) - T((m1 + m2) * g * l1) * sin(x(0)),
                                        k * s * x(2) * x(2) - T(m2 * g * l2) * sin(x(1)));
    a = mass.ldlt().solve(forces);
  }

  template <class T>
  void step(const Eigen::Matrix<T, 4, 1>& x, const Eigen::Matrix<T, 1, 1>& u,
            Eigen::Matrix<T, 4, 1>& next) const {
    Eigen::Matrix<T, 2, 1> a;
    acceleration(x, u, a);
    next.template tail<2>() = x.template tail<2>() + T(dt) * a;
    next.template head<2>() = x.template head<2>() + T(dt) * next.template tail<2>();
  }

  /// E(x), conserved when τ = 0.
  [[nodiscard]] double energy(const Eigen::Vector4d& x) const {
    const double c = std::cos(x(0) - x(1));
    const double kinetic = 0.5 * (m1 + m2) * l1 * l1 * x(2) * x(2) +
                           0.5 * m2 * l2 * l2 * x(3) * x(3) + m2 * l1 * l2 * c * x(2) * x(3);
    return kinetic - (m1 + m2) * g * l1 * std::cos(x(0)) - m2 * g * l2 * std::cos(x(1));
  }
};

}  // namespace sbptt::examples
