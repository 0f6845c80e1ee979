#pragma once
/// \file The equations of the physical cart pole (`CartPoleModel::Physical`, cartpole.hpp): P
/// rigid poles hinged side by side on one cart of mass m_c, total mass M_P = m_c + P m. From the
/// Lagrangian (pole i: centre at x + l sin θ_i, inertia m l²/3 about it):
///
///     D = M_P − ¾ m Σ_i cos²θ_i,   ẍ = (F + Σ_i (m l θ̇_i² sin θ_i − ¾ m g sin θ_i cos θ_i)) / D
///     θ̈_i = ¾ (g sin θ_i − ẍ cos θ_i) / l
///
/// Semi-implicit Euler as the reference model: θ̇_i' = θ̇_i + dt θ̈_i, θ_i' = θ_i + dt θ̇_i',
/// ẋ' = ẋ + dt ẍ, x' = x + dt ẋ'. Every pole feels the others through ẍ, so A is dense in the
/// poles, but Aᵀλ stays O(P): the pole adjoints reach ẍ through one sum.
///
/// State layout (cartpole.hpp): x, ẋ, θ_1, θ̇_1, …, θ_P, θ̇_P; control: F.
#include <cmath>

#include <Eigen/Core>

#include "sbptt/core/types.hpp"

namespace sbptt::detail {

/// The physical model's constants and equations for `Poles` poles (`Eigen::Dynamic`: `poles`).
/// `X`, `L` (and the outputs): a state vector or a batch's column.
template <class Scalar, int Poles>
struct CartPolePhysical {
  using PoleVector = Eigen::Matrix<Scalar, Poles, 1>;  ///< one entry per pole

  Index poles = 0;
  Scalar dt{};          ///< T / Nt
  Scalar gravity{};     ///< g
  Scalar half_length{};  ///< l
  Scalar pole_mass{};   ///< m
  Scalar total_mass{};  ///< M_P

  /// ẍ and its partials in θ_i, θ̇_i (into `d_theta`, `d_omega` when not null) and F.
  template <class X>
  Scalar cart_accel(const X& x, Scalar force, PoleVector* d_theta = nullptr,
                    PoleVector* d_omega = nullptr, Scalar* d_force = nullptr) const {
    using std::cos, std::sin;
    const Scalar m = pole_mass, l = half_length, g = gravity, quarter3 = Scalar(0.75);
    Scalar numer = force, denom = total_mass;
    for (Index i = 0; i < poles; ++i) {
      const Scalar s = sin(x(2 + 2 * i)), c = cos(x(2 + 2 * i)), w = x(3 + 2 * i);
      numer += m * l * w * w * s - quarter3 * m * g * s * c;
      denom -= quarter3 * m * c * c;
    }
    const Scalar accel = numer / denom;
    if (d_force != nullptr) *d_force = Scalar(1) / denom;
    if (d_theta == nullptr) return accel;
    for (Index i = 0; i < poles; ++i) {
      const Scalar s = sin(x(2 + 2 * i)), c = cos(x(2 + 2 * i)), w = x(3 + 2 * i);
      const Scalar numer_theta = m * l * w * w * c - quarter3 * m * g * (c * c - s * s);
      const Scalar denom_theta = Scalar(2) * quarter3 * m * c * s;
      (*d_theta)(i) = (numer_theta - accel * denom_theta) / denom;
      (*d_omega)(i) = Scalar(2) * m * l * w * s / denom;
    }
    return accel;
  }

  /// ẍ with all its partials.
  struct Partials {
    Scalar cart_accel, d_force;
    PoleVector d_theta, d_omega;
  };
  template <class X>
  [[nodiscard]] Partials partials(const X& x, Scalar force) const {
    Partials p;
    p.d_theta.resize(poles);
    p.d_omega.resize(poles);
    p.cart_accel = cart_accel(x, force, &p.d_theta, &p.d_omega, &p.d_force);
    return p;
  }

  template <class X, class Y>
  void step(const X& x, Scalar force, Y&& x_next) const {
    using std::cos, std::sin;
    const Scalar accel_cart = cart_accel(x, force);
    const Scalar k = Scalar(0.75) / half_length;
    for (Index i = 0; i < poles; ++i) {
      const Index j = 2 + 2 * i;
      const Scalar accel = k * (gravity * sin(x(j)) - accel_cart * cos(x(j)));
      x_next(j + 1) = x(j + 1) + dt * accel;
      x_next(j) = x(j) + dt * x_next(j + 1);
    }
    x_next(1) = x(1) + dt * accel_cart;
    x_next(0) = x(0) + dt * x_next(1);
  }

  /// Rows of A and B below the kinematic entries the caller set. ∂θ̈_i/∂θ_j =
  /// k (δ_ij (g cos θ_i + ẍ sin θ_i) − cos θ_i ∂ẍ/∂θ_j), k = ¾ / l: dense through ẍ.
  template <class X, class A, class B>
  void jacobians(const X& x, Scalar force, A& a, B& b) const {
    using std::cos, std::sin;
    // A named struct, not a structured binding: clang before 16 cannot capture bindings.
    const Partials p = partials(x, force);
    const Scalar dt2 = dt * dt, k = Scalar(0.75) / half_length;
    auto rows = [&](Index r, Scalar own_theta, Scalar own_omega, Scalar gain) {
      // Position row r and velocity row r + 1 of an acceleration gain·ẍ + own terms.
      for (Index j = 0; j < poles; ++j) {
        const Index col = 2 + 2 * j;
        const Scalar theta = gain * p.d_theta(j) + (col == r ? own_theta : Scalar(0));
        const Scalar omega = gain * p.d_omega(j) + (col == r ? own_omega : Scalar(0));
        a(r, col) += dt2 * theta;
        a(r, col + 1) += dt2 * omega;
        a(r + 1, col) += dt * theta;
        a(r + 1, col + 1) += dt * omega;
      }
      b(r) = dt2 * gain * p.d_force;
      b(r + 1) = dt * gain * p.d_force;
    };
    rows(0, Scalar(0), Scalar(0), Scalar(1));
    for (Index i = 0; i < poles; ++i) {
      const Index r = 2 + 2 * i;
      const Scalar s = sin(x(r)), c = cos(x(r));
      a(r, r) = Scalar(1);
      a(r, r + 1) = dt;
      a(r + 1, r + 1) = Scalar(1);
      rows(r, k * (gravity * c + p.cart_accel * s), Scalar(0), -k * c);
    }
  }

  /// Aᵀλ and Bᵀλ in O(P): the pole adjoints reach ẍ through one sum, Σ_i k cos θ_i ā_i.
  /// `lambda_x`: sized by the caller.
  template <class X, class L, class LX>
  void vjp(const X& x, Scalar force, const L& lambda, LX* lambda_x, Scalar* lambda_u) const {
    using std::cos, std::sin;
    const auto [accel_cart, d_force, d_theta, d_omega] = partials(x, force);
    const Scalar dt2 = dt * dt, k = Scalar(0.75) / half_length;
    Scalar cart_adj = dt2 * lambda(0) + dt * lambda(1);  // adjoint of ẍ, completed below
    for (Index i = 0; i < poles; ++i) {
      const Index r = 2 + 2 * i;
      cart_adj -= k * cos(x(r)) * (dt2 * lambda(r) + dt * lambda(r + 1));
    }
    if (lambda_u != nullptr) *lambda_u = cart_adj * d_force;
    if (lambda_x == nullptr) return;
    (*lambda_x)(0) = lambda(0);
    (*lambda_x)(1) = dt * lambda(0) + lambda(1);
    for (Index i = 0; i < poles; ++i) {
      const Index r = 2 + 2 * i;
      const Scalar pole_adj = dt2 * lambda(r) + dt * lambda(r + 1);
      const Scalar own = k * (gravity * cos(x(r)) + accel_cart * sin(x(r)));
      (*lambda_x)(r) = lambda(r) + pole_adj * own + cart_adj * d_theta(i);
      (*lambda_x)(r + 1) = dt * lambda(r) + lambda(r + 1) + cart_adj * d_omega(i);
    }
  }
};

}  // namespace sbptt::detail
