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
/// state. This is the benchmark the paper's numbers come from, and the default.
///
/// `CartPoleModel::Physical` switches both off: P rigid poles hinged side by side on one cart
/// of mass m_c = M − m (M stays the mass with one pole, so one pole is the gym system exactly),
/// total mass M_P = m_c + P m. From the Lagrangian (pole i: centre at x + l sin θ_i, inertia
/// m l²/3 about it):
///
///     D = M_P − ¾ m Σ_i cos²θ_i,   ẍ = (F + Σ_i (m l θ̇_i² sin θ_i − ¾ m g sin θ_i cos θ_i)) / D
///     θ̈_i = ¾ (g sin θ_i − ẍ cos θ_i) / l
///
/// so every pole feels the others through the cart. Its energy ½ M_P ẋ² + Σ_i (m l cos θ_i ẋ θ̇_i
/// + ⅔ m l² θ̇_i² + m g l cos θ_i) is conserved with F = 0 (the tests check the integrator's
/// drift against it).
///
/// Derivative structure used below: x_next = E x + G a(θ, θ̇, F) with a = (ẍ, θ̈_1, …, θ̈_P),
/// E the kinematic part of the integrator, and G = (dt², dt) per position/velocity pair.
/// Hence A = E + G ∂a/∂x, B = G ∂a/∂F, and Aᵀλ = Eᵀλ + (∂a/∂x)ᵀ Gᵀλ, which needs only the
/// per-pole partials of θ̈_i and ẍ: O(P) work, and no N × N matrix.
///
/// The equations live in cartpole_reference.hpp and cartpole_physical.hpp, the batched path
/// in cartpole_lanes.hpp; this header holds the simulator, its task's loss and its
/// initial states.
#include <cmath>
#include <numbers>
#include <type_traits>

#include <Eigen/Core>

#include "sbptt/core/error.hpp"
#include "sbptt/core/rng.hpp"
#include "sbptt/core/types.hpp"
#include "sbptt/core/unroll.hpp"
#include "sbptt/sim/cartpole_lanes.hpp"
#include "sbptt/sim/cartpole_physical.hpp"
#include "sbptt/sim/cartpole_reference.hpp"
#include "sbptt/sim/lane_rows.hpp"

namespace sbptt {

/// Which equations of motion `CartPole` integrates (see its file comment).
enum class CartPoleModel {
  Reference,  ///< the paper's: decoupled poles, total mass M whatever the pole count
  Physical,   ///< poles hinged on one cart, coupled through it; total mass M + (P − 1) m
};

/// Horizon and physical constants of `CartPole`. Defaults are the paper's (§5).
struct CartPoleOptions {
  double horizon = 1.0;      ///< T, simulated time of one rollout (> 0)
  Index steps = 100;         ///< Nt, time steps per rollout (> 0); dt = T / Nt
  double gravity = 9.8;      ///< g
  double pole_mass = 0.1;    ///< m, mass of every pole (≥ 0, < 4/3 · total_mass)
  double total_mass = 1.1;   ///< M, fixed regardless of the pole count (> 0)
  double half_length = 0.5;  ///< l, half the pole length (> 0)
  CartPoleModel model = CartPoleModel::Reference;
};

namespace detail {

/// State size for a pole count known at compile time (`Eigen::Dynamic` stays dynamic).
constexpr int cartpole_state_size(int poles) {
  return poles == Eigen::Dynamic ? Eigen::Dynamic : 2 + 2 * poles;
}

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
    detail::require(options.model == CartPoleModel::Reference ||
                        options.pole_mass < options.total_mass,
                    "CartPole: pole_mass = ", options.pole_mass, " with the physical model, "
                    "expected m < total_mass = ", options.total_mass, " (a cart of positive mass)");
    options_ = options;
    reference_.dt = static_cast<Scalar>(options.horizon / static_cast<double>(options.steps));
    reference_.gravity = static_cast<Scalar>(options.gravity);
    reference_.mass_ratio = static_cast<Scalar>(options.pole_mass / options.total_mass);
    reference_.inv_total_mass = static_cast<Scalar>(1.0 / options.total_mass);
    reference_.half_length = static_cast<Scalar>(options.half_length);
    reference_.ml_over_m =
        static_cast<Scalar>(options.pole_mass * options.half_length / options.total_mass);
    physical_.poles = poles;
    physical_.dt = reference_.dt;
    physical_.gravity = reference_.gravity;
    physical_.half_length = reference_.half_length;
    physical_.pole_mass = static_cast<Scalar>(options.pole_mass);
    physical_.total_mass = static_cast<Scalar>(
        options.total_mass + static_cast<double>(poles - 1) * options.pole_mass);
  }

  [[nodiscard]] Index poles() const { return poles_; }
  [[nodiscard]] Index state_dim() const { return 2 + 2 * poles_; }
  [[nodiscard]] Index control_dim() const { return 1; }
  [[nodiscard]] Scalar dt() const { return reference_.dt; }
  [[nodiscard]] Index steps() const { return options_.steps; }
  [[nodiscard]] const Options& options() const { return options_; }

  /// x_next = P(x, u). x, x_next: state_dim; u: 1. `x_next` may alias `x`.
  void step(const State& x, const Control& u, State& x_next) const {
    check_size(x, "x");
    x_next.resize(state_dim());
    if (options_.model == CartPoleModel::Physical) return physical_.step(x, u(0), x_next);
    const Scalar force = u(0);
    Scalar q_sum(0);
    for (Index i = 0; i < poles_; ++i) {
      const Index k = 2 + 2 * i;
      q_sum += reference_.pole_step(x(k), x(k + 1), force, x_next(k), x_next(k + 1));
    }
    reference_.cart_step(x(0), x(1), force, q_sum, x_next(0), x_next(1));
  }

  /// A = ∂x_next/∂x (state_dim × state_dim), B = ∂x_next/∂F (state_dim × 1), analytic.
  void jacobians(const State& x, const Control& u, StateJacobian& a, ControlJacobian& b) const {
    check_size(x, "x");
    const Index n = state_dim();
    const Scalar dt = reference_.dt, dt2 = dt * dt;
    a.setZero(n, n);
    b.setZero(n, 1);
    a(0, 0) = Scalar(1);
    a(0, 1) = dt;
    a(1, 1) = Scalar(1);
    if (options_.model == CartPoleModel::Physical) return physical_.jacobians(x, u(0), a, b);
    const Scalar ml_over_m = reference_.ml_over_m;
    Scalar cart_force = reference_.inv_total_mass;  // ∂ẍ/∂F, completed by the pole sums below
    for (Index i = 0; i < poles_; ++i) {
      const Index k = 2 + 2 * i;
      const auto t = reference_.pole_terms(x(k), x(k + 1), u(0));
      // Pole rows: θ' = θ + dt θ̇ + dt² θ̈, θ̇' = θ̇ + dt θ̈.
      a(k, k) = Scalar(1) + dt2 * t.accel_theta;
      a(k, k + 1) = dt + dt2 * t.accel_omega;
      a(k + 1, k) = dt * t.accel_theta;
      a(k + 1, k + 1) = Scalar(1) + dt * t.accel_omega;
      b(k) = dt2 * t.accel_force;
      b(k + 1) = dt * t.accel_force;
      // Cart rows: ẍ depends on pole i through q_i only.
      const Scalar cart_theta = ml_over_m * t.q_theta;
      const Scalar cart_omega = ml_over_m * t.q_omega;
      a(0, k) = dt2 * cart_theta;
      a(0, k + 1) = dt2 * cart_omega;
      a(1, k) = dt * cart_theta;
      a(1, k + 1) = dt * cart_omega;
      cart_force += ml_over_m * t.q_force;
    }
    b(0) = dt2 * cart_force;
    b(1) = dt * cart_force;
  }

  /// *lambda_x = Aᵀ λ (state_dim), *lambda_u = Bᵀ λ (1), in O(P) without forming A or B.
  /// Either pointer may be null to skip that product. `lambda_x` must not alias `lambda`.
  void vjp(const State& x, const Control& u, const State& lambda, State* lambda_x,
           Control* lambda_u) const {
    check_size(x, "x");
    check_size(lambda, "lambda");
    if (lambda_x == nullptr && lambda_u == nullptr) return;
    if (lambda_x != nullptr) lambda_x->resize(state_dim());
    if (options_.model == CartPoleModel::Physical)
      return physical_.vjp(x, u(0), lambda, lambda_x,
                           lambda_u == nullptr ? nullptr : &(*lambda_u)(0));
    const Scalar dt = reference_.dt, dt2 = dt * dt;
    // Gᵀλ: the adjoint of each acceleration (ẍ first, then θ̈_i per pole).
    const Scalar cart_adj = dt2 * lambda(0) + dt * lambda(1);
    Scalar force_adj = reference_.inv_total_mass * cart_adj;
    for (Index i = 0; i < poles_; ++i) {
      const Index k = 2 + 2 * i;
      force_adj += reference_.pole_vjp(x(k), x(k + 1), u(0), lambda(k), lambda(k + 1), cart_adj,
                                       lambda_x ? &(*lambda_x)(k) : nullptr,
                                       lambda_x ? &(*lambda_x)(k + 1) : nullptr);
    }
    if (lambda_x != nullptr) {
      (*lambda_x)(0) = lambda(0);
      (*lambda_x)(1) = dt * lambda(0) + lambda(1);
    }
    if (lambda_u != nullptr) (*lambda_u)(0) = force_adj;
  }

  /// `step` for every column of x (state_dim × B) and u (1 × B) into x_next (resized to
  /// state_dim × B; it may be x itself). Float and double only (other number types, such as
  /// automatic differentiation's, step sample by sample): the samples run side by side in SIMD
  /// lanes (lane_rows.hpp) through the same pole equations as `step`, with a vectorised sine
  /// and cosine (core/sine_cosine.hpp; Eigen's for float), which round differently from
  /// std::sin and std::cos, so the two agree to rounding, not bit for bit. A column's result
  /// does not depend on the other columns. A block of fewer samples than lanes takes a lane per
  /// pole and sample where that needs fewer passes than one per pole, with the same numbers
  /// (cartpole_lanes.hpp). The physical model runs `step`'s equations column by column.
  /// One machine copy (SBPTT_ONE_COPY) for the engine's paths that step a batch: the forward
  /// pass, its parts on several threads and the evaluation (docs/design.md).
  SBPTT_ONE_COPY void step_batch(const Matrix<Scalar>& x, const Matrix<Scalar>& u,
                                 Matrix<Scalar>& x_next) const
    requires FloatOrDouble<Scalar>
  {
    using Lanes = detail::LaneRows<Scalar>;
    check_batch(x, u, "step_batch");
    x_next.resize(state_dim(), x.cols());
    for (Index first = 0; first < x.cols(); first += Lanes::kLanes) {
      const int count = Lanes::count(x.cols(), first);
      if (options_.model == CartPoleModel::Physical) {
        for (Index b = first; b < first + count; ++b)
          physical_.step(x.col(b), u(0, b), x_next.col(b));
      } else {
        detail::CartPoleLanes<Scalar>{reference_, poles_}.step(x, u, x_next, first, count);
      }
    }
  }

  /// `vjp` for every column of x (state_dim × B), u (1 × B) and lambda (state_dim × B):
  /// lambda_x (if not null) resized to state_dim × B, lambda_u to 1 × B; it must not be
  /// lambda. As `step_batch`: SIMD lanes, equal to `vjp` to rounding, one machine copy.
  SBPTT_ONE_COPY void vjp_batch(const Matrix<Scalar>& x, const Matrix<Scalar>& u,
                                const Matrix<Scalar>& lambda, Matrix<Scalar>* lambda_x,
                                Matrix<Scalar>* lambda_u) const
    requires FloatOrDouble<Scalar>
  {
    using Lanes = detail::LaneRows<Scalar>;
    check_batch(x, u, "vjp_batch");
    detail::require(lambda.rows() == state_dim() && lambda.cols() == x.cols(),
                    "CartPole::vjp_batch: lambda is ", lambda.rows(), " x ", lambda.cols(),
                    "; expected ", state_dim(), " x ", x.cols());
    detail::require(lambda_x != &lambda, "CartPole::vjp_batch: lambda_x is lambda; expected ",
                    "another matrix");
    if (lambda_x != nullptr) lambda_x->resize(state_dim(), x.cols());
    if (lambda_u != nullptr) lambda_u->resize(1, x.cols());
    for (Index first = 0; first < x.cols(); first += Lanes::kLanes) {
      const int count = Lanes::count(x.cols(), first);
      if (options_.model != CartPoleModel::Physical) {
        detail::CartPoleLanes<Scalar>{reference_, poles_}.vjp(x, u, lambda, lambda_x, lambda_u,
                                                              first, count);
        continue;
      }
      for (Index b = first; b < first + count; ++b) {
        Scalar* control_out = lambda_u ? &(*lambda_u)(0, b) : nullptr;
        if (lambda_x != nullptr) {
          auto column = lambda_x->col(b);
          physical_.vjp(x.col(b), u(0, b), lambda.col(b), &column, control_out);
        } else {
          physical_.vjp(x.col(b), u(0, b), lambda.col(b), static_cast<State*>(nullptr),
                        control_out);
        }
      }
    }
  }

private:
  void check_batch(const Matrix<Scalar>& x, const Matrix<Scalar>& u, const char* caller) const {
    detail::require(x.rows() == state_dim(), "CartPole::", caller, ": x has ", x.rows(),
                    " rows; expected state_dim() = ", state_dim(), " (one sample per column)");
    detail::require(u.rows() == 1 && u.cols() == x.cols(), "CartPole::", caller, ": u is ",
                    u.rows(), " x ", u.cols(), "; expected 1 x ", x.cols(), " (one force per sample)");
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
  detail::CartPoleReference<Scalar> reference_;
  detail::CartPolePhysical<Scalar, Poles> physical_;
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
    using std::cos, std::sin;
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

/// Draws `count` initial states of the paper's distribution for `poles` poles (or links of
/// `CartChain`, whose layout is the same): (2 + 2·poles) × count, one sample per column;
/// x, ẋ, θ̇_i ~ U[−1, 1), θ_i = π + U[−1, 1)·π/6 (hanging ± 30°). Draws are taken per sample in
/// state-layout order, so sample j depends only on the stream position.
template <class Scalar>
[[nodiscard]] Matrix<Scalar> cartpole_initial_states(Index poles, Rng& rng, Index count) {
  detail::require(poles >= 1, "cartpole_initial_states: poles = ", poles, ", expected >= 1");
  detail::require(count >= 0, "cartpole_initial_states: count = ", count, ", expected >= 0");
  constexpr double pi = std::numbers::pi;
  Matrix<Scalar> states(2 + 2 * poles, count);
  for (Index j = 0; j < count; ++j) {
    states(0, j) = static_cast<Scalar>(rng.uniform(-1.0, 1.0));
    states(1, j) = static_cast<Scalar>(rng.uniform(-1.0, 1.0));
    for (Index i = 0; i < poles; ++i) {
      states(2 + 2 * i, j) = static_cast<Scalar>(pi + rng.uniform(-1.0, 1.0) * pi / 6.0);
      states(3 + 2 * i, j) = static_cast<Scalar>(rng.uniform(-1.0, 1.0));
    }
  }
  return states;
}

/// The same for the poles of `sim`.
template <class Scalar, int Poles>
[[nodiscard]] Matrix<Scalar> cartpole_initial_states(const CartPole<Scalar, Poles>& sim, Rng& rng,
                                                     Index count) {
  return cartpole_initial_states<Scalar>(sim.poles(), rng, count);
}

}  // namespace sbptt
