#pragma once
/// \file Multi-pole cart pole swing-up (paper §5), with analytic Jacobians and a matrix-free VJP.
///
/// Equations (θ = 0 upright; g, pole mass m, total mass M, half-length l; force F):
///
///     A_i  = (F + m l θ̇_i² sin θ_i) / M
///     θ̈_i  = (g sin θ_i − cos θ_i A_i) / (l (4/3 − m cos²θ_i / M))
///     ẍ    = (F + m l Σ_i (θ̇_i² sin θ_i − θ̈_i cos θ_i)) / M
///
/// Semi-implicit (symplectic) Euler, dt = T / Nt:
///
///     θ̇_i' = θ̇_i + dt θ̈_i,   θ_i' = θ_i + dt θ̇_i',   ẋ' = ẋ + dt ẍ,   x' = x + dt ẋ'
///
/// State layout (size 2 + 2P): x, ẋ, θ_1, θ̇_1, …, θ_P, θ̇_P. Control: the force F (size 1).
///
/// Reference quirks kept on purpose (paper §8.8): M = 1.1 does not grow with the pole count, and
/// each θ̈_i depends only on F and its own pole, so the poles do not feel each other or the cart
/// state. This is the benchmark the paper's numbers come from; a physical multi-pendulum would
/// be a different simulator, not an option of this one.
///
/// Derivative structure used below: x_next = E x + G a(θ, θ̇, F) with a = (ẍ, θ̈_1, …, θ̈_P),
/// E the kinematic part of the integrator, and G = (dt², dt) per position/velocity pair.
/// Hence A = E + G ∂a/∂x, B = G ∂a/∂F, and Aᵀλ = Eᵀλ + (∂a/∂x)ᵀ Gᵀλ, which needs only the
/// per-pole partials of θ̈_i and ẍ: O(P) work, and no N × N matrix.
#include <cmath>
#include <numbers>

#include <Eigen/Core>

#include "sbptt/bptt/objective.hpp"
#include "sbptt/core/error.hpp"
#include "sbptt/core/rng.hpp"
#include "sbptt/core/types.hpp"

namespace sbptt {

/// Horizon and physical constants of `CartPole`. Defaults are the paper's (§5).
struct CartPoleOptions {
  double horizon = 1.0;      ///< T, simulated time of one rollout (> 0)
  Index steps = 100;         ///< Nt, time steps per rollout (> 0); dt = T / Nt
  double gravity = 9.8;      ///< g
  double pole_mass = 0.1;    ///< m, mass of every pole (≥ 0, < 4/3 · total_mass)
  double total_mass = 1.1;   ///< M, fixed regardless of the pole count (> 0)
  double half_length = 0.5;  ///< l, half the pole length (> 0)
};

namespace detail {

/// State size for a pole count known at compile time (`Eigen::Dynamic` stays dynamic).
constexpr int cartpole_state_size(int poles) {
  return poles == Eigen::Dynamic ? Eigen::Dynamic : 2 + 2 * poles;
}

/// One pole's angular acceleration θ̈ and its contribution q = θ̇² sin θ − θ̈ cos θ to the cart
/// sum, with their partial derivatives in θ, θ̇ and F.
template <class Scalar>
struct PoleTerms {
  Scalar accel, accel_theta, accel_omega, accel_force;
  Scalar q, q_theta, q_omega, q_force;
};

}  // namespace detail

/// The paper's multi-pole cart (see the file comment for the equations and the state layout).
///
/// `Poles` fixes the pole count at compile time; with `Eigen::Dynamic` it is a constructor
/// argument. Immutable and thread-safe: every member function is `const`.
template <class ScalarT = double, int Poles = 1>
class CartPole {
  static_assert(Poles == Eigen::Dynamic || Poles >= 1, "CartPole needs at least one pole");

public:
  using Scalar = ScalarT;
  using Options = CartPoleOptions;
  static constexpr int kStateSize = detail::cartpole_state_size(Poles);
  using State = Eigen::Matrix<Scalar, kStateSize, 1>;               ///< 2 + 2P
  using Control = Eigen::Matrix<Scalar, 1, 1>;                      ///< the force F
  using StateJacobian = Eigen::Matrix<Scalar, kStateSize, kStateSize>;  ///< (2+2P) × (2+2P)
  using ControlJacobian = Eigen::Matrix<Scalar, kStateSize, 1>;         ///< (2+2P) × 1

  /// Fixed pole count. Throws InvalidArgument on a bad option.
  explicit CartPole(const Options& options = {})
    requires(Poles != Eigen::Dynamic)
      : CartPole(Poles, options) {}

  /// Pole count at run time (must equal `Poles` when that is fixed). Throws InvalidArgument on
  /// a bad count or option.
  explicit CartPole(Index poles, const Options& options = {}) : poles_(poles) {
    detail::require(poles >= 1, "CartPole: poles = ", poles, ", expected >= 1");
    detail::require(Poles == Eigen::Dynamic || poles == Poles, "CartPole: poles = ", poles,
                    ", expected the template's pole count ", Poles);
    detail::require(std::isfinite(options.horizon) && options.horizon > 0,
                    "CartPole: horizon = ", options.horizon, ", expected a finite T > 0");
    detail::require(options.steps >= 1, "CartPole: steps = ", options.steps, ", expected >= 1");
    detail::require(std::isfinite(options.gravity), "CartPole: gravity = ", options.gravity,
                    ", expected a finite number");
    detail::require(std::isfinite(options.total_mass) && options.total_mass > 0,
                    "CartPole: total_mass = ", options.total_mass, ", expected a finite M > 0");
    detail::require(std::isfinite(options.half_length) && options.half_length > 0,
                    "CartPole: half_length = ", options.half_length, ", expected a finite l > 0");
    // The denominator l (4/3 − m cos²θ / M) must stay positive for every θ.
    detail::require(std::isfinite(options.pole_mass) && options.pole_mass >= 0 &&
                        3 * options.pole_mass < 4 * options.total_mass,
                    "CartPole: pole_mass = ", options.pole_mass,
                    ", expected 0 <= m < 4/3 * total_mass = ", 4 * options.total_mass / 3);
    options_ = options;
    dt_ = static_cast<Scalar>(options.horizon / static_cast<double>(options.steps));
    gravity_ = static_cast<Scalar>(options.gravity);
    mass_ratio_ = static_cast<Scalar>(options.pole_mass / options.total_mass);
    inv_total_mass_ = static_cast<Scalar>(1.0 / options.total_mass);
    half_length_ = static_cast<Scalar>(options.half_length);
    ml_over_m_ = static_cast<Scalar>(options.pole_mass * options.half_length / options.total_mass);
  }

  [[nodiscard]] Index poles() const { return poles_; }
  [[nodiscard]] Index state_dim() const { return 2 + 2 * poles_; }
  [[nodiscard]] Index control_dim() const { return 1; }
  [[nodiscard]] Scalar dt() const { return dt_; }
  [[nodiscard]] Index steps() const { return options_.steps; }
  [[nodiscard]] const Options& options() const { return options_; }

  /// x_next = P(x, u). x, x_next: state_dim; u: 1. `x_next` may alias `x`.
  void step(const State& x, const Control& u, State& x_next) const {
    check_size(x, "x");
    x_next.resize(state_dim());
    const Scalar force = u(0);
    Scalar q_sum(0);
    for (Index i = 0; i < poles_; ++i) {
      const Index k = 2 + 2 * i;
      const auto t = pole_terms(x(k), x(k + 1), force);
      q_sum += t.q;
      x_next(k + 1) = x(k + 1) + dt_ * t.accel;  // every read of pole i happens before its writes
      x_next(k) = x(k) + dt_ * x_next(k + 1);
    }
    const Scalar cart_accel = inv_total_mass_ * force + ml_over_m_ * q_sum;
    x_next(1) = x(1) + dt_ * cart_accel;
    x_next(0) = x(0) + dt_ * x_next(1);
  }

  /// A = ∂x_next/∂x (state_dim × state_dim), B = ∂x_next/∂F (state_dim × 1), analytic.
  void jacobians(const State& x, const Control& u, StateJacobian& a, ControlJacobian& b) const {
    check_size(x, "x");
    const Index n = state_dim();
    const Scalar dt2 = dt_ * dt_;
    a.setZero(n, n);
    b.setZero(n, 1);
    a(0, 0) = Scalar(1);
    a(0, 1) = dt_;
    a(1, 1) = Scalar(1);
    Scalar cart_force = inv_total_mass_;  // ∂ẍ/∂F, completed by the pole sums below
    for (Index i = 0; i < poles_; ++i) {
      const Index k = 2 + 2 * i;
      const auto t = pole_terms(x(k), x(k + 1), u(0));
      // Pole rows: θ' = θ + dt θ̇ + dt² θ̈, θ̇' = θ̇ + dt θ̈.
      a(k, k) = Scalar(1) + dt2 * t.accel_theta;
      a(k, k + 1) = dt_ + dt2 * t.accel_omega;
      a(k + 1, k) = dt_ * t.accel_theta;
      a(k + 1, k + 1) = Scalar(1) + dt_ * t.accel_omega;
      b(k) = dt2 * t.accel_force;
      b(k + 1) = dt_ * t.accel_force;
      // Cart rows: ẍ depends on pole i through q_i only.
      const Scalar cart_theta = ml_over_m_ * t.q_theta;
      const Scalar cart_omega = ml_over_m_ * t.q_omega;
      a(0, k) = dt2 * cart_theta;
      a(0, k + 1) = dt2 * cart_omega;
      a(1, k) = dt_ * cart_theta;
      a(1, k + 1) = dt_ * cart_omega;
      cart_force += ml_over_m_ * t.q_force;
    }
    b(0) = dt2 * cart_force;
    b(1) = dt_ * cart_force;
  }

  /// *lambda_x = Aᵀ λ (state_dim), *lambda_u = Bᵀ λ (1), in O(P) without forming A or B.
  /// Either pointer may be null to skip that product. `lambda_x` must not alias `lambda`.
  void vjp(const State& x, const Control& u, const State& lambda, State* lambda_x,
           Control* lambda_u) const {
    check_size(x, "x");
    check_size(lambda, "lambda");
    if (lambda_x == nullptr && lambda_u == nullptr) return;
    const Scalar dt2 = dt_ * dt_;
    // Gᵀλ: the adjoint of each acceleration (ẍ first, then θ̈_i per pole).
    const Scalar cart_adj = dt2 * lambda(0) + dt_ * lambda(1);
    Scalar force_adj = inv_total_mass_ * cart_adj;
    if (lambda_x != nullptr) {
      lambda_x->resize(state_dim());
      (*lambda_x)(0) = lambda(0);
      (*lambda_x)(1) = dt_ * lambda(0) + lambda(1);
    }
    for (Index i = 0; i < poles_; ++i) {
      const Index k = 2 + 2 * i;
      const auto t = pole_terms(x(k), x(k + 1), u(0));
      const Scalar pole_adj = dt2 * lambda(k) + dt_ * lambda(k + 1);
      force_adj += pole_adj * t.accel_force + cart_adj * ml_over_m_ * t.q_force;
      if (lambda_x != nullptr) {
        (*lambda_x)(k) = lambda(k) + pole_adj * t.accel_theta + cart_adj * ml_over_m_ * t.q_theta;
        (*lambda_x)(k + 1) = dt_ * lambda(k) + lambda(k + 1) + pole_adj * t.accel_omega +
                             cart_adj * ml_over_m_ * t.q_omega;
      }
    }
    if (lambda_u != nullptr) (*lambda_u)(0) = force_adj;
  }

private:
  /// θ̈ of one pole and its cart term q, with partials (quotient rule on N / D).
  [[nodiscard]] detail::PoleTerms<Scalar> pole_terms(Scalar theta, Scalar omega,
                                                     Scalar force) const {
    using std::cos;
    using std::sin;
    const Scalar s = sin(theta);
    const Scalar c = cos(theta);
    const Scalar w2 = omega * omega;
    // A = (F + m l θ̇² s)/M; ml_over_m_ = m l / M.
    const Scalar push = inv_total_mass_ * force + ml_over_m_ * w2 * s;
    const Scalar push_theta = ml_over_m_ * w2 * c;
    const Scalar push_omega = Scalar(2) * ml_over_m_ * omega * s;
    const Scalar numer = gravity_ * s - c * push;
    const Scalar numer_theta = gravity_ * c + s * push - c * push_theta;
    const Scalar denom = half_length_ * (Scalar(4) / Scalar(3) - mass_ratio_ * c * c);
    const Scalar denom_theta = Scalar(2) * half_length_ * mass_ratio_ * c * s;
    const Scalar inv_denom = Scalar(1) / denom;

    detail::PoleTerms<Scalar> t;
    t.accel = numer * inv_denom;
    t.accel_theta = (numer_theta - t.accel * denom_theta) * inv_denom;
    t.accel_omega = -c * push_omega * inv_denom;
    t.accel_force = -c * inv_total_mass_ * inv_denom;
    t.q = w2 * s - t.accel * c;
    t.q_theta = w2 * c - t.accel_theta * c + t.accel * s;
    t.q_omega = Scalar(2) * omega * s - t.accel_omega * c;
    t.q_force = -t.accel_force * c;
    return t;
  }

  /// Fixed sizes are checked by the compiler; dynamic ones here, since a mismatch would
  /// otherwise read out of bounds in a Release build.
  void check_size(const State& v, const char* name) const {
    if constexpr (kStateSize == Eigen::Dynamic) {
      detail::require(v.size() == state_dim(), "CartPole: ", name, " has size ", v.size(),
                      ", expected state_dim() = ", state_dim());
    }
  }

  Index poles_;
  Options options_{};
  Scalar dt_{}, gravity_{}, mass_ratio_{}, inv_total_mass_{}, half_length_{}, ml_over_m_{};
};

/// Final-state loss ℓ(x) = 1 − mean_i cos θ_i (0 when every pole is upright, 2 when all hang).
///
/// The pole count is read from the state size (2 + 2P), so one functor serves fixed and
/// dynamic cart poles.
template <class ScalarT = double, int Poles = 1>
struct CartPoleUprightLoss {
  using Scalar = ScalarT;
  using State = typename CartPole<Scalar, Poles>::State;

  /// Returns ℓ(x); if `grad` is not null sets *grad = ∂ℓ/∂x (state_dim: sin θ_i / P on the
  /// angles, 0 elsewhere). Throws InvalidArgument if x.size() is not 2 + 2P with P ≥ 1.
  Scalar operator()(const State& x, State* grad) const {
    detail::require(x.size() >= 4 && x.size() % 2 == 0, "CartPoleUprightLoss: state size ",
                    x.size(), ", expected 2 + 2 * poles with poles >= 1");
    using std::cos;
    using std::sin;
    const Index poles = (x.size() - 2) / 2;
    const Scalar inv_poles = Scalar(1) / static_cast<Scalar>(poles);
    if (grad != nullptr) grad->setZero(x.size());
    Scalar cos_sum(0);
    for (Index i = 0; i < poles; ++i) {
      const Scalar theta = x(2 + 2 * i);
      cos_sum += cos(theta);
      if (grad != nullptr) (*grad)(2 + 2 * i) = sin(theta) * inv_poles;
    }
    return Scalar(1) - cos_sum * inv_poles;
  }
};

/// The paper's cart-pole objective: `CartPoleUprightLoss` on the final state only, no control
/// regulariser.
template <class Scalar = double, int Poles = 1>
[[nodiscard]] Objective<CartPoleUprightLoss<Scalar, Poles>> cartpole_objective() {
  Objective<CartPoleUprightLoss<Scalar, Poles>> objective;
  objective.timing = LossTiming::Final;
  objective.step_weight = 1.0;
  objective.control_weight = 0.0;
  return objective;
}

/// Draws `count` initial states of the paper's distribution (state_dim × count, one sample per
/// column): x, ẋ, θ̇_i ~ U[−1, 1), θ_i = π + U[−1, 1)·π/6 (hanging ± 30°). Draws are taken per
/// sample in state-layout order, so sample j depends only on the stream position.
template <class Scalar, int Poles>
[[nodiscard]] Matrix<Scalar> cartpole_initial_states(const CartPole<Scalar, Poles>& sim, Rng& rng,
                                                     Index count) {
  detail::require(count >= 0, "cartpole_initial_states: count = ", count, ", expected >= 0");
  constexpr double pi = std::numbers::pi;
  Matrix<Scalar> states(sim.state_dim(), count);
  for (Index j = 0; j < count; ++j) {
    states(0, j) = static_cast<Scalar>(rng.uniform(-1.0, 1.0));
    states(1, j) = static_cast<Scalar>(rng.uniform(-1.0, 1.0));
    for (Index i = 0; i < sim.poles(); ++i) {
      states(2 + 2 * i, j) = static_cast<Scalar>(pi + rng.uniform(-1.0, 1.0) * pi / 6.0);
      states(3 + 2 * i, j) = static_cast<Scalar>(rng.uniform(-1.0, 1.0));
    }
  }
  return states;
}

}  // namespace sbptt
