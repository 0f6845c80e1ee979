#pragma once
/// \file The equations of the paper's cart pole (`CartPoleModel::Reference`, cartpole.hpp) for
/// one pole and for the cart, written once for a scalar and for a block of SIMD lanes.
///
/// Equations (θ = 0 upright; g, pole mass m, total mass M, half-length l; force F):
///
///     A_i  = (F + m l θ̇_i² sin θ_i) / M
///     θ̈_i  = (g sin θ_i − cos θ_i A_i) / (l (4/3 − m cos²θ_i / M))
///     q_i  = θ̇_i² sin θ_i − θ̈_i cos θ_i,    ẍ = F / M + (m l / M) Σ_i q_i
///
/// Semi-implicit Euler, dt = T / Nt: θ̇_i' = θ̇_i + dt θ̈_i, θ_i' = θ_i + dt θ̇_i',
/// ẋ' = ẋ + dt ẍ, x' = x + dt ẋ'.
///
/// State layout (cartpole.hpp): x, ẋ, θ_1, θ̇_1, …, θ_P, θ̇_P; control: F. Each pole enters the
/// cart only through q_i, so a step is P independent pole updates and one cart update from
/// their sum, and the VJP is O(P).
#include "sbptt/core/sine_cosine.hpp"

namespace sbptt::detail {

/// One pole's angular acceleration θ̈ and its contribution q = θ̇² sin θ − θ̈ cos θ to the cart
/// sum, with their partial derivatives in θ, θ̇ and F.
template <class Scalar>
struct PoleTerms {
  Scalar accel, accel_theta, accel_omega, accel_force;
  Scalar q, q_theta, q_omega, q_force;
};

/// The reference model's constants and its per-pole and cart equations. `V` is `Scalar` for one
/// sample, or a lane array for a block of samples (cartpole_lanes.hpp).
template <class Scalar>
struct CartPoleReference {
  Scalar dt{};              ///< T / Nt
  Scalar gravity{};         ///< g
  Scalar mass_ratio{};      ///< m / M
  Scalar inv_total_mass{};  ///< 1 / M
  Scalar half_length{};     ///< l
  Scalar ml_over_m{};       ///< m l / M

  /// θ̈ of one pole and its cart term q, with partials (quotient rule on N / D).
  template <class V>
  [[nodiscard]] PoleTerms<V> pole_terms(const V& theta, const V& omega, const V& force) const {
    V s, c;
    sine_cosine(theta, s, c);
    const V w2 = omega * omega;
    // A = (F + m l θ̇² s)/M; ml_over_m = m l / M.
    const V push = inv_total_mass * force + ml_over_m * w2 * s;
    const V push_theta = ml_over_m * w2 * c;
    const V push_omega = Scalar(2) * ml_over_m * omega * s;
    const V numer = gravity * s - c * push;
    const V numer_theta = gravity * c + s * push - c * push_theta;
    const V denom = half_length * (Scalar(4) / Scalar(3) - mass_ratio * c * c);
    const V denom_theta = Scalar(2) * half_length * mass_ratio * c * s;
    const V inv_denom = Scalar(1) / denom;

    PoleTerms<V> t;
    t.accel = numer * inv_denom;
    t.accel_theta = (numer_theta - t.accel * denom_theta) * inv_denom;
    t.accel_omega = -c * push_omega * inv_denom;
    t.accel_force = -c * inv_total_mass * inv_denom;
    t.q = w2 * s - t.accel * c;
    t.q_theta = w2 * c - t.accel_theta * c + t.accel * s;
    t.q_omega = Scalar(2) * omega * s - t.accel_omega * c;
    t.q_force = -t.accel_force * c;
    return t;
  }

  /// One pole's step: θ̇' = θ̇ + dt θ̈, θ' = θ + dt θ̇'. Returns its cart term q_i. Every read
  /// of the pole happens before its writes, so the outputs may alias the inputs.
  template <class V>
  V pole_step(const V& theta, const V& omega, const V& force, V& theta_next,
              V& omega_next) const {
    const auto t = pole_terms(theta, omega, force);
    const V theta_now = theta;
    omega_next = omega + dt * t.accel;
    theta_next = theta_now + dt * omega_next;
    return t.q;
  }

  /// The cart's step, from the poles' sum Σ q_i: ẍ = F/M + (m l/M) Σ q_i.
  template <class V>
  void cart_step(const V& position, const V& velocity, const V& force, const V& q_sum,
                 V& position_next, V& velocity_next) const {
    const V position_now = position;
    velocity_next = velocity + dt * (inv_total_mass * force + ml_over_m * q_sum);
    position_next = position_now + dt * velocity_next;
  }

  /// One pole's part of the VJP, with ā_x = cart_adj the adjoint of ẍ (Gᵀλ): its rows of Aᵀλ
  /// (when `lambda_theta_out` is not null) and its term of Bᵀλ (returned).
  template <class V>
  V pole_vjp(const V& theta, const V& omega, const V& force, const V& lambda_theta,
             const V& lambda_omega, const V& cart_adj, V* lambda_theta_out,
             V* lambda_omega_out) const {
    const auto t = pole_terms(theta, omega, force);
    const Scalar dt2 = dt * dt;
    const V pole_adj = dt2 * lambda_theta + dt * lambda_omega;
    if (lambda_theta_out != nullptr) {
      *lambda_theta_out =
          lambda_theta + pole_adj * t.accel_theta + cart_adj * ml_over_m * t.q_theta;
      *lambda_omega_out = dt * lambda_theta + lambda_omega + pole_adj * t.accel_omega +
                          cart_adj * ml_over_m * t.q_omega;
    }
    return pole_adj * t.accel_force + cart_adj * ml_over_m * t.q_force;
  }
};

}  // namespace sbptt::detail
