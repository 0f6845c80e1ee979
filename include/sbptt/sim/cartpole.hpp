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
#include <cmath>
#include <numbers>
#include <type_traits>

#include <Eigen/Core>

#include "sbptt/core/error.hpp"
#include "sbptt/core/rng.hpp"
#include "sbptt/core/types.hpp"
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
    detail::require(options.model == CartPoleModel::Reference ||
                        options.pole_mass < options.total_mass,
                    "CartPole: pole_mass = ", options.pole_mass, " with the physical model, "
                    "expected m < total_mass = ", options.total_mass, " (a cart of positive mass)");
    options_ = options;
    dt_ = static_cast<Scalar>(options.horizon / static_cast<double>(options.steps));
    gravity_ = static_cast<Scalar>(options.gravity);
    mass_ratio_ = static_cast<Scalar>(options.pole_mass / options.total_mass);
    inv_total_mass_ = static_cast<Scalar>(1.0 / options.total_mass);
    half_length_ = static_cast<Scalar>(options.half_length);
    ml_over_m_ = static_cast<Scalar>(options.pole_mass * options.half_length / options.total_mass);
    pole_mass_ = static_cast<Scalar>(options.pole_mass);
    physical_total_mass_ = static_cast<Scalar>(
        options.total_mass + static_cast<double>(poles - 1) * options.pole_mass);
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
    if (options_.model == CartPoleModel::Physical) return physical_step(x, u(0), x_next);
    const Scalar force = u(0);
    Scalar q_sum(0);
    for (Index i = 0; i < poles_; ++i) {
      const Index k = 2 + 2 * i;
      q_sum += reference_pole_step(x(k), x(k + 1), force, x_next(k), x_next(k + 1));
    }
    reference_cart_step(x(0), x(1), force, q_sum, x_next(0), x_next(1));
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
    if (options_.model == CartPoleModel::Physical) return physical_jacobians(x, u, a, b);
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
    if (lambda_x != nullptr) lambda_x->resize(state_dim());
    if (options_.model == CartPoleModel::Physical)
      return physical_vjp(x, u(0), lambda, lambda_x,
                          lambda_u == nullptr ? nullptr : &(*lambda_u)(0));
    const Scalar dt2 = dt_ * dt_;
    // Gᵀλ: the adjoint of each acceleration (ẍ first, then θ̈_i per pole).
    const Scalar cart_adj = dt2 * lambda(0) + dt_ * lambda(1);
    Scalar force_adj = inv_total_mass_ * cart_adj;
    for (Index i = 0; i < poles_; ++i) {
      const Index k = 2 + 2 * i;
      force_adj += reference_pole_vjp(x(k), x(k + 1), u(0), lambda(k), lambda(k + 1), cart_adj,
                                      lambda_x ? &(*lambda_x)(k) : nullptr,
                                      lambda_x ? &(*lambda_x)(k + 1) : nullptr);
    }
    if (lambda_x != nullptr) {
      (*lambda_x)(0) = lambda(0);
      (*lambda_x)(1) = dt_ * lambda(0) + lambda(1);
    }
    if (lambda_u != nullptr) (*lambda_u)(0) = force_adj;
  }

  /// `step` for every column of x (state_dim × B) and u (1 × B) into x_next (resized to
  /// state_dim × B; it may be x itself). Float only: the samples run side by side in SIMD lanes
  /// (lane_rows.hpp) through the same pole equations as `step`, with Eigen's vectorised sine
  /// and cosine, which round differently from std::sin and std::cos, so the two agree to
  /// rounding, not bit for bit. A column's result does not depend on the other columns. A
  /// block of fewer samples than lanes takes a lane per pole and sample where that needs fewer
  /// blocks than one per pole (`pole_lanes_pay`), with the same numbers. The physical model
  /// runs `step`'s equations column by column. (In double Eigen has no
  /// vectorised sine: lanes measured slower than `step` per sample, 797 against 467 ns for 8
  /// samples of 4 poles, so double keeps the per-sample path.)
  void step_batch(const Matrix<Scalar>& x, const Matrix<Scalar>& u, Matrix<Scalar>& x_next) const
    requires std::is_same_v<Scalar, float>
  {
    using Lanes = detail::LaneRows<Scalar>;
    using LaneValues = typename Lanes::Values;
    check_batch(x, u, "step_batch");
    x_next.resize(state_dim(), x.cols());
    for (Index first = 0; first < x.cols(); first += Lanes::kLanes) {
      const int count = Lanes::count(x.cols(), first);
      if (options_.model == CartPoleModel::Physical) {
        for (Index b = first; b < first + count; ++b)
          physical_step(x.col(b), u(0, b), x_next.col(b));
        continue;
      }
      if (pole_lanes_pay(count)) {
        for (int done = 0; done < count; done += pole_lane_samples())
          step_pole_lanes(x, u, x_next, first + done, std::min(pole_lane_samples(), count - done));
        continue;
      }
      auto load = [&](const Matrix<Scalar>& m, Index row) {
        return Lanes::load(m, row, first, count);
      };
      const LaneValues force = load(u, 0);
      LaneValues q_sum = LaneValues::Zero(), position, velocity;
      for (Index i = 0; i < poles_; ++i) {
        const Index k = 2 + 2 * i;
        q_sum += reference_pole_step(load(x, k), load(x, k + 1), force, position, velocity);
        Lanes::store(position, x_next, k, first, count);
        Lanes::store(velocity, x_next, k + 1, first, count);
      }
      reference_cart_step(load(x, 0), load(x, 1), force, q_sum, position, velocity);
      Lanes::store(position, x_next, 0, first, count);
      Lanes::store(velocity, x_next, 1, first, count);
    }
  }

  /// `vjp` for every column of x (state_dim × B), u (1 × B) and lambda (state_dim × B):
  /// lambda_x (if not null) resized to state_dim × B, lambda_u to 1 × B; it must not be
  /// lambda. As `step_batch`: SIMD lanes, equal to `vjp` to rounding.
  void vjp_batch(const Matrix<Scalar>& x, const Matrix<Scalar>& u, const Matrix<Scalar>& lambda,
                 Matrix<Scalar>* lambda_x, Matrix<Scalar>* lambda_u) const
    requires std::is_same_v<Scalar, float>
  {
    using Lanes = detail::LaneRows<Scalar>;
    using LaneValues = typename Lanes::Values;
    check_batch(x, u, "vjp_batch");
    detail::require(lambda.rows() == state_dim() && lambda.cols() == x.cols(),
                    "CartPole::vjp_batch: lambda is ", lambda.rows(), " x ", lambda.cols(),
                    "; expected ", state_dim(), " x ", x.cols());
    detail::require(lambda_x != &lambda, "CartPole::vjp_batch: lambda_x is lambda; expected ",
                    "another matrix");
    if (lambda_x != nullptr) lambda_x->resize(state_dim(), x.cols());
    if (lambda_u != nullptr) lambda_u->resize(1, x.cols());
    const Scalar dt2 = dt_ * dt_;
    for (Index first = 0; first < x.cols(); first += Lanes::kLanes) {
      const int count = Lanes::count(x.cols(), first);
      if (options_.model == CartPoleModel::Physical) {
        for (Index b = first; b < first + count; ++b) {
          Scalar* control_out = lambda_u ? &(*lambda_u)(0, b) : nullptr;
          if (lambda_x != nullptr) {
            auto column = lambda_x->col(b);
            physical_vjp(x.col(b), u(0, b), lambda.col(b), &column, control_out);
          } else {
            physical_vjp(x.col(b), u(0, b), lambda.col(b), static_cast<State*>(nullptr),
                         control_out);
          }
        }
        continue;
      }
      if (pole_lanes_pay(count)) {
        for (int done = 0; done < count; done += pole_lane_samples())
          vjp_pole_lanes(x, u, lambda, lambda_x, lambda_u, first + done,
                         std::min(pole_lane_samples(), count - done));
        continue;
      }
      auto load = [&](const Matrix<Scalar>& m, Index row) {
        return Lanes::load(m, row, first, count);
      };
      const LaneValues force = load(u, 0), lambda_position = load(lambda, 0);
      const LaneValues lambda_velocity = load(lambda, 1);
      const LaneValues cart_adj = dt2 * lambda_position + dt_ * lambda_velocity;
      LaneValues force_adj = inv_total_mass_ * cart_adj, theta_out, omega_out;
      for (Index i = 0; i < poles_; ++i) {
        const Index k = 2 + 2 * i;
        force_adj += reference_pole_vjp(load(x, k), load(x, k + 1), force, load(lambda, k),
                                        load(lambda, k + 1), cart_adj,
                                        lambda_x ? &theta_out : nullptr,
                                        lambda_x ? &omega_out : nullptr);
        if (lambda_x == nullptr) continue;
        Lanes::store(theta_out, *lambda_x, k, first, count);
        Lanes::store(omega_out, *lambda_x, k + 1, first, count);
      }
      if (lambda_x != nullptr) {
        Lanes::store(lambda_position, *lambda_x, 0, first, count);
        Lanes::store(dt_ * lambda_position + lambda_velocity, *lambda_x, 1, first, count);
      }
      if (lambda_u != nullptr) Lanes::store(force_adj, *lambda_u, 0, first, count);
    }
  }

private:
  /// ẍ of the physical model and its partials in θ_i, θ̇_i (into `d_theta`, `d_omega` when
  /// not null) and F. The pole accelerations follow as ¾ (g sin θ_i − ẍ cos θ_i) / l.
  using PoleVector = Eigen::Matrix<Scalar, Poles, 1>;  ///< one entry per pole

  template <class X>
  Scalar physical_cart_accel(const X& x, Scalar force, PoleVector* d_theta = nullptr,
                             PoleVector* d_omega = nullptr, Scalar* d_force = nullptr) const {
    using std::cos, std::sin;
    const Scalar m = pole_mass_, l = half_length_, g = gravity_, quarter3 = Scalar(0.75);
    Scalar numer = force, denom = physical_total_mass_;
    for (Index i = 0; i < poles_; ++i) {
      const Scalar s = sin(x(2 + 2 * i)), c = cos(x(2 + 2 * i)), w = x(3 + 2 * i);
      numer += m * l * w * w * s - quarter3 * m * g * s * c;
      denom -= quarter3 * m * c * c;
    }
    const Scalar accel = numer / denom;
    if (d_force != nullptr) *d_force = Scalar(1) / denom;
    if (d_theta == nullptr) return accel;
    for (Index i = 0; i < poles_; ++i) {
      const Scalar s = sin(x(2 + 2 * i)), c = cos(x(2 + 2 * i)), w = x(3 + 2 * i);
      const Scalar numer_theta = m * l * w * w * c - quarter3 * m * g * (c * c - s * s);
      const Scalar denom_theta = Scalar(2) * quarter3 * m * c * s;
      (*d_theta)(i) = (numer_theta - accel * denom_theta) / denom;
      (*d_omega)(i) = Scalar(2) * m * l * w * s / denom;
    }
    return accel;
  }

  /// ẍ of the physical model with all its partials.
  struct PhysicalPartials {
    Scalar cart_accel, d_force;
    PoleVector d_theta, d_omega;
  };
  template <class X>
  [[nodiscard]] PhysicalPartials physical_partials(const X& x, Scalar force) const {
    PhysicalPartials p;
    p.d_theta.resize(poles_);
    p.d_omega.resize(poles_);
    p.cart_accel = physical_cart_accel(x, force, &p.d_theta, &p.d_omega, &p.d_force);
    return p;
  }

  /// `X`, `Y`: a State or a batch's column (`step_batch`).
  template <class X, class Y>
  void physical_step(const X& x, Scalar force, Y&& x_next) const {
    using std::cos, std::sin;
    const Scalar cart_accel = physical_cart_accel(x, force);
    const Scalar k = Scalar(0.75) / half_length_;
    for (Index i = 0; i < poles_; ++i) {
      const Index j = 2 + 2 * i;
      const Scalar accel = k * (gravity_ * sin(x(j)) - cart_accel * cos(x(j)));
      x_next(j + 1) = x(j + 1) + dt_ * accel;
      x_next(j) = x(j) + dt_ * x_next(j + 1);
    }
    x_next(1) = x(1) + dt_ * cart_accel;
    x_next(0) = x(0) + dt_ * x_next(1);
  }

  /// Rows of A and B below the kinematic entries the caller set. ∂θ̈_i/∂θ_j =
  /// k (δ_ij (g cos θ_i + ẍ sin θ_i) − cos θ_i ∂ẍ/∂θ_j), k = ¾ / l: dense through ẍ.
  void physical_jacobians(const State& x, const Control& u, StateJacobian& a,
                          ControlJacobian& b) const {
    using std::cos, std::sin;
    // A named struct, not a structured binding: clang before 16 cannot capture bindings.
    const PhysicalPartials p = physical_partials(x, u(0));
    const Scalar dt2 = dt_ * dt_, k = Scalar(0.75) / half_length_;
    auto rows = [&](Index r, Scalar own_theta, Scalar own_omega, Scalar gain) {
      // Position row r and velocity row r + 1 of an acceleration gain·ẍ + own terms.
      for (Index j = 0; j < poles_; ++j) {
        const Index col = 2 + 2 * j;
        const Scalar theta = gain * p.d_theta(j) + (col == r ? own_theta : Scalar(0));
        const Scalar omega = gain * p.d_omega(j) + (col == r ? own_omega : Scalar(0));
        a(r, col) += dt2 * theta;
        a(r, col + 1) += dt2 * omega;
        a(r + 1, col) += dt_ * theta;
        a(r + 1, col + 1) += dt_ * omega;
      }
      b(r) = dt2 * gain * p.d_force;
      b(r + 1) = dt_ * gain * p.d_force;
    };
    rows(0, Scalar(0), Scalar(0), Scalar(1));
    for (Index i = 0; i < poles_; ++i) {
      const Index r = 2 + 2 * i;
      const Scalar s = sin(x(r)), c = cos(x(r));
      a(r, r) = Scalar(1);
      a(r, r + 1) = dt_;
      a(r + 1, r + 1) = Scalar(1);
      rows(r, k * (gravity_ * c + p.cart_accel * s), Scalar(0), -k * c);
    }
  }

  /// Aᵀλ and Bᵀλ in O(P): the pole adjoints reach ẍ through one sum, Σ_i k cos θ_i ā_i.
  /// `lambda_x`: sized by the caller. `X`, `L`, `LX`: a State or a batch's column.
  template <class X, class L, class LX>
  void physical_vjp(const X& x, Scalar force, const L& lambda, LX* lambda_x,
                    Scalar* lambda_u) const {
    using std::cos, std::sin;
    const auto [cart_accel, d_force, d_theta, d_omega] = physical_partials(x, force);
    const Scalar dt2 = dt_ * dt_, k = Scalar(0.75) / half_length_;
    Scalar cart_adj = dt2 * lambda(0) + dt_ * lambda(1);  // adjoint of ẍ, completed below
    for (Index i = 0; i < poles_; ++i) {
      const Index r = 2 + 2 * i;
      cart_adj -= k * cos(x(r)) * (dt2 * lambda(r) + dt_ * lambda(r + 1));
    }
    if (lambda_u != nullptr) *lambda_u = cart_adj * d_force;
    if (lambda_x == nullptr) return;
    (*lambda_x)(0) = lambda(0);
    (*lambda_x)(1) = dt_ * lambda(0) + lambda(1);
    for (Index i = 0; i < poles_; ++i) {
      const Index r = 2 + 2 * i;
      const Scalar pole_adj = dt2 * lambda(r) + dt_ * lambda(r + 1);
      const Scalar own = k * (gravity_ * cos(x(r)) + cart_accel * sin(x(r)));
      (*lambda_x)(r) = lambda(r) + pole_adj * own + cart_adj * d_theta(i);
      (*lambda_x)(r + 1) = dt_ * lambda(r) + lambda(r + 1) + cart_adj * d_omega(i);
    }
  }

  /// θ̈ of one pole and its cart term q, with partials (quotient rule on N / D). `V` is
  /// `Scalar` for one sample, or a lane array for a block of samples (`step_batch`).
  template <class V>
  [[nodiscard]] detail::PoleTerms<V> pole_terms(const V& theta, const V& omega,
                                                const V& force) const {
    using std::cos, std::sin;
    const V s = sin(theta);
    const V c = cos(theta);
    const V w2 = omega * omega;
    // A = (F + m l θ̇² s)/M; ml_over_m_ = m l / M.
    const V push = inv_total_mass_ * force + ml_over_m_ * w2 * s;
    const V push_theta = ml_over_m_ * w2 * c;
    const V push_omega = Scalar(2) * ml_over_m_ * omega * s;
    const V numer = gravity_ * s - c * push;
    const V numer_theta = gravity_ * c + s * push - c * push_theta;
    const V denom = half_length_ * (Scalar(4) / Scalar(3) - mass_ratio_ * c * c);
    const V denom_theta = Scalar(2) * half_length_ * mass_ratio_ * c * s;
    const V inv_denom = Scalar(1) / denom;

    detail::PoleTerms<V> t;
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

  /// Pole i of the reference step: θ̇' = θ̇ + dt θ̈, θ' = θ + dt θ̇'. Returns its cart term q_i.
  /// Every read of the pole happens before its writes, so the outputs may alias the inputs.
  template <class V>
  V reference_pole_step(const V& theta, const V& omega, const V& force, V& theta_next,
                        V& omega_next) const {
    const auto t = pole_terms(theta, omega, force);
    const V theta_now = theta;
    omega_next = omega + dt_ * t.accel;
    theta_next = theta_now + dt_ * omega_next;
    return t.q;
  }

  /// The cart of the reference step, from the poles' sum Σ q_i: ẍ = F/M + (m l/M) Σ q_i.
  template <class V>
  void reference_cart_step(const V& position, const V& velocity, const V& force, const V& q_sum,
                           V& position_next, V& velocity_next) const {
    const V position_now = position;
    velocity_next = velocity + dt_ * (inv_total_mass_ * force + ml_over_m_ * q_sum);
    position_next = position_now + dt_ * velocity_next;
  }

  /// Pole i of the reference vjp, with ā_x = cart_adj the adjoint of ẍ (Gᵀλ): its rows of Aᵀλ
  /// (when `lambda_theta_out` is not null) and its term of Bᵀλ (returned).
  template <class V>
  V reference_pole_vjp(const V& theta, const V& omega, const V& force, const V& lambda_theta,
                       const V& lambda_omega, const V& cart_adj, V* lambda_theta_out,
                       V* lambda_omega_out) const {
    const auto t = pole_terms(theta, omega, force);
    const Scalar dt2 = dt_ * dt_;
    const V pole_adj = dt2 * lambda_theta + dt_ * lambda_omega;
    if (lambda_theta_out != nullptr) {
      *lambda_theta_out =
          lambda_theta + pole_adj * t.accel_theta + cart_adj * ml_over_m_ * t.q_theta;
      *lambda_omega_out = dt_ * lambda_theta + lambda_omega + pole_adj * t.accel_omega +
                          cart_adj * ml_over_m_ * t.q_omega;
    }
    return pole_adj * t.accel_force + cart_adj * ml_over_m_ * t.q_force;
  }

  /// Samples per block with one lane per pole and sample (lane b·P + i), 0 if P > a block.
  [[nodiscard]] int pole_lane_samples() const {
    return static_cast<int>(detail::LaneRows<Scalar>::kLanes / poles_);
  }

  /// Whether `count` samples of the reference model fill fewer blocks with a lane per pole
  /// and sample than the P blocks (one per pole) of a lane per sample: a part of a batch
  /// split over threads (4 samples of 4 poles: 1 block instead of 4), the paper's batch of 8
  /// (2 instead of 4). Every lane computes what it computes in the other layout, and the sums
  /// over the poles are taken per sample in pole order in both, so the two give the same
  /// numbers bit for bit (tests/test_sim_cartpole.cpp).
  [[nodiscard]] bool pole_lanes_pay(int count) const {
    const int per_block = pole_lane_samples();
    return per_block > 0 && (count + per_block - 1) / per_block < poles_;
  }

  /// Row `offset` (0: θ_i, 1: θ̇_i) of every pole of samples first … first + count − 1 of `m`
  /// into lanes b·P + i; the other lanes are 0, as in `LaneRows::load`.
  template <class Values>
  void load_pole_lanes(const Matrix<Scalar>& m, Index offset, Index first, int count,
                       Values& v) const {
    v.setZero();
    for (int b = 0; b < count; ++b)
      for (Index i = 0; i < poles_; ++i) v(b * poles_ + i) = m(2 + 2 * i + offset, first + b);
  }

  template <class Values>
  void store_pole_lanes(const Values& v, Matrix<Scalar>& m, Index offset, Index first,
                        int count) const {
    for (int b = 0; b < count; ++b)
      for (Index i = 0; i < poles_; ++i) m(2 + 2 * i + offset, first + b) = v(b * poles_ + i);
  }

  /// Each sample's value (`per_sample`, lane b) in all of its pole lanes b·P + i.
  template <class Values>
  [[nodiscard]] Values spread_to_poles(const Values& per_sample, int count) const {
    Values v = Values::Zero();
    for (int b = 0; b < count; ++b)
      for (Index i = 0; i < poles_; ++i) v(b * poles_ + i) = per_sample(b);
    return v;
  }

  /// `sum` (lane b: sample b) += the pole lanes b·P + i of `terms`, in pole order.
  template <class Values>
  void add_pole_lanes(const Values& terms, int count, Values& sum) const {
    for (int b = 0; b < count; ++b)
      for (Index i = 0; i < poles_; ++i) sum(b) += terms(b * poles_ + i);
  }

  /// `step_batch` of the reference model for samples first … first + count − 1, a lane per
  /// pole and sample.
  void step_pole_lanes(const Matrix<Scalar>& x, const Matrix<Scalar>& u, Matrix<Scalar>& x_next,
                       Index first, int count) const {
    using Lanes = detail::LaneRows<Scalar>;
    using LaneValues = typename Lanes::Values;
    LaneValues theta, omega, position, velocity;
    load_pole_lanes(x, 0, first, count, theta);
    load_pole_lanes(x, 1, first, count, omega);
    const LaneValues force = Lanes::load(u, 0, first, count);
    const LaneValues q = reference_pole_step(theta, omega, spread_to_poles(force, count),
                                             position, velocity);
    store_pole_lanes(position, x_next, 0, first, count);
    store_pole_lanes(velocity, x_next, 1, first, count);
    LaneValues q_sum = LaneValues::Zero();
    add_pole_lanes(q, count, q_sum);
    reference_cart_step(Lanes::load(x, 0, first, count), Lanes::load(x, 1, first, count), force,
                        q_sum, position, velocity);
    Lanes::store(position, x_next, 0, first, count);
    Lanes::store(velocity, x_next, 1, first, count);
  }

  /// `vjp_batch` of the reference model for samples first … first + count − 1, a lane per
  /// pole and sample.
  void vjp_pole_lanes(const Matrix<Scalar>& x, const Matrix<Scalar>& u,
                      const Matrix<Scalar>& lambda, Matrix<Scalar>* lambda_x,
                      Matrix<Scalar>* lambda_u, Index first, int count) const {
    using Lanes = detail::LaneRows<Scalar>;
    using LaneValues = typename Lanes::Values;
    const LaneValues force = Lanes::load(u, 0, first, count);
    const LaneValues lambda_position = Lanes::load(lambda, 0, first, count);
    const LaneValues lambda_velocity = Lanes::load(lambda, 1, first, count);
    const Scalar dt2 = dt_ * dt_;
    const LaneValues cart_adj = dt2 * lambda_position + dt_ * lambda_velocity;
    LaneValues force_adj = inv_total_mass_ * cart_adj;
    LaneValues theta, omega, lambda_theta, lambda_omega, theta_out, omega_out;
    load_pole_lanes(x, 0, first, count, theta);
    load_pole_lanes(x, 1, first, count, omega);
    load_pole_lanes(lambda, 0, first, count, lambda_theta);
    load_pole_lanes(lambda, 1, first, count, lambda_omega);
    const LaneValues force_terms = reference_pole_vjp(
        theta, omega, spread_to_poles(force, count), lambda_theta, lambda_omega,
        spread_to_poles(cart_adj, count), lambda_x ? &theta_out : nullptr,
        lambda_x ? &omega_out : nullptr);
    add_pole_lanes(force_terms, count, force_adj);
    if (lambda_x != nullptr) {
      store_pole_lanes(theta_out, *lambda_x, 0, first, count);
      store_pole_lanes(omega_out, *lambda_x, 1, first, count);
      Lanes::store(lambda_position, *lambda_x, 0, first, count);
      Lanes::store(dt_ * lambda_position + lambda_velocity, *lambda_x, 1, first, count);
    }
    if (lambda_u != nullptr) Lanes::store(force_adj, *lambda_u, 0, first, count);
  }

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
  Scalar dt_{}, gravity_{}, mass_ratio_{}, inv_total_mass_{}, half_length_{}, ml_over_m_{};
  Scalar pole_mass_{}, physical_total_mass_{};  ///< m and M_P of the physical model
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
