#pragma once
/// \file Continuous dynamics ẋ = f(x, u) stepped by a chosen integrator, as a `Simulator` whose
/// Jacobians and VJP are those of the discrete map, through every stage.
///
/// A model gives either the first-order dynamics or, for a position/velocity system, the
/// accelerations (templated on the scalar, like an `AutoDiffSimulator` model):
///
///     template <class T> void derivative(const ColumnOf<T, N>& x, const ColumnOf<T, K>& u,
///                                        ColumnOf<T, N>& xdot) const;           // ẋ = f(x, u)
///     template <class T> void acceleration(const ColumnOf<T, N>& x, const ColumnOf<T, K>& u,
///                                          ColumnOf<T, N/2>& a) const;          // q̈ = a(x, u)
///
/// with `static constexpr int kStateSize, kControlSize`; a second-order model also names its
/// layout, `static constexpr StateLayout kLayout` (positions and velocities `Stacked` as
/// (q, v), the default, or `Interleaved` as (q₀, v₀, q₁, v₁, …)). Optionally the model gives f's
/// (or a's) Jacobians analytically, in the `Integrated`'s `Scalar` (templated or not):
///
///     void derivative_jacobians(const ColumnOf<Scalar, N>& x, const ColumnOf<Scalar, K>& u,
///                               Eigen::Matrix<Scalar, N, N>& fx,           // ∂f/∂x
///                               Eigen::Matrix<Scalar, N, K>& fu) const;    // ∂f/∂u
///     void acceleration_jacobians(const ColumnOf<Scalar, N>& x, const ColumnOf<Scalar, K>& u,
///                                 Eigen::Matrix<Scalar, N/2, N>& ax,       // ∂a/∂x
///                                 Eigen::Matrix<Scalar, N/2, K>& au) const;  // ∂a/∂u
///
/// otherwise they are automatic (autodiff.hpp). A member of either name that cannot be called
/// so is a compile error with this signature, not a silent switch to automatic Jacobians.
///
/// Explicit Runge–Kutta methods (tableau a, b; h = dt; s stages):
///
///     X_i = x + h Σ_{j<i} a_ij k_j,   k_i = f(X_i, u),   x' = x + h Σ_i b_i k_i
///
///     ExplicitEuler: b = (1)                         order 1
///     Heun (RK2):    a₂₁ = 1, b = (½, ½)             order 2
///     RungeKutta4:   a₂₁ = a₃₂ = ½, a₄₃ = 1, b = (⅙, ⅓, ⅓, ⅙)   order 4
///
/// Exact derivatives of the discrete map, with F_i = ∂f/∂x and G_i = ∂f/∂u at (X_i, u):
///
///     forward:  ∂X_i = [I | 0] + h Σ_{j<i} a_ij ∂k_j,   ∂k_i = F_i ∂X_i + [0 | G_i],
///               [A | B] = [I | 0] + h Σ_i b_i ∂k_i
///     reverse:  k̄_i = h b_i λ + h Σ_{j>i} a_ji X̄_j,   X̄_i = F_iᵀ k̄_i,
///               Aᵀλ = λ + Σ_i X̄_i,   Bᵀλ = Σ_i G_iᵀ k̄_i
///
/// Semi-implicit (symplectic) Euler, for second-order models only (order 1, and its energy
/// error stays bounded over long horizons instead of drifting):
///
///     v' = v + h a(x, u),   q' = q + h v'
///     v̄ = λ_v + h λ_q,   Aᵀλ = (λ_q, v̄) + h a_xᵀ v̄,   Bᵀλ = h a_uᵀ v̄
///
/// Cost of `vjp`: one stage pass that also forms each stage's F_i, G_i (automatic: one dual
/// pass with N + K directions per stage), then s transposed products. RK4 costs about four times
/// explicit Euler. Fixed sizes allocate nothing.
#include <array>
#include <cmath>
#include <concepts>
#include <utility>

#include <Eigen/Core>

#include "sbptt/core/error.hpp"
#include "sbptt/core/types.hpp"
#include "sbptt/sim/autodiff.hpp"
#include "sbptt/sim/integrated_model.hpp"

namespace sbptt {

/// Where positions and velocities sit in the state of a second-order model (N = 2·dof).
enum class StateLayout {
  Stacked,      ///< (q₀, …, q_{d−1}, v₀, …, v_{d−1})
  Interleaved,  ///< (q₀, v₀, q₁, v₁, …)
};

/// Explicit Euler: x' = x + h f(x, u). Order 1.
struct ExplicitEuler {
  static constexpr int kStages = 1;
  static constexpr std::array<double, 1> b{1.0};
  static constexpr double a(int, int) { return 0.0; }
};

/// Heun's method (explicit trapezoid, RK2). Order 2.
struct Heun {
  static constexpr int kStages = 2;
  static constexpr std::array<double, 2> b{0.5, 0.5};
  static constexpr double a(int i, int j) { return i == 1 && j == 0 ? 1.0 : 0.0; }
};

/// The classic fourth-order Runge–Kutta method. Order 4.
struct RungeKutta4 {
  static constexpr int kStages = 4;
  static constexpr std::array<double, 4> b{1.0 / 6.0, 1.0 / 3.0, 1.0 / 3.0, 1.0 / 6.0};
  static constexpr double a(int i, int j) {
    return (i == 1 && j == 0) || (i == 2 && j == 1) ? 0.5 : (i == 3 && j == 2 ? 1.0 : 0.0);
  }
};

/// Semi-implicit (symplectic) Euler for second-order models: v' = v + h a, q' = q + h v'.
struct SemiImplicitEuler {};

namespace detail {

template <class M>
constexpr StateLayout layout_of() {
  if constexpr (requires { M::kLayout; }) {
    return M::kLayout;
  } else {
    return StateLayout::Stacked;
  }
}

/// The model's right-hand side (f for a first-order model, a for a second-order one) in any
/// scalar, with its Jacobians analytic when the model has them, else automatic.
template <class Model, class Scalar>
class RightHandSide {
public:
  static constexpr int kStateSize = Model::kStateSize, kControlSize = Model::kControlSize;
  static constexpr bool kSecondOrder = IsSecondOrder<Model>;
  static constexpr int kRhsSize = kSecondOrder ? half_or_dynamic(kStateSize) : kStateSize;
  static constexpr StateLayout kLayout = layout_of<Model>();
  using State = ColumnOf<Scalar, kStateSize>;
  using Control = ColumnOf<Scalar, kControlSize>;
  using Rhs = ColumnOf<Scalar, kRhsSize>;
  using RhsByState = Eigen::Matrix<Scalar, kRhsSize, kStateSize>;
  using RhsByControl = Eigen::Matrix<Scalar, kRhsSize, kControlSize>;

  explicit RightHandSide(const Model& model) : model_(model) {}

  [[nodiscard]] Index rows(Index n) const { return kSecondOrder ? n / 2 : n; }

  /// Index of position / velocity i (i < N/2) of a second-order state of size n.
  static Index position(Index i, Index /*n*/) {
    return kLayout == StateLayout::Interleaved ? 2 * i : i;
  }
  static Index velocity(Index i, Index n) {
    return kLayout == StateLayout::Interleaved ? 2 * i + 1 : n / 2 + i;
  }

  template <class X, class U, class Out>
  void evaluate(const X& x, const U& u, Out& out) const {
    if constexpr (kSecondOrder) {
      model_.acceleration(x, u, out);
    } else {
      model_.derivative(x, u, out);
    }
  }

  /// value = g(x, u), gx = ∂g/∂x, gu = ∂g/∂u.
  void evaluate_with_jacobians(const State& x, const Control& u, Rhs& value, RhsByState& gx,
                               RhsByControl& gu) const {
    if constexpr (kSecondOrder && HasAccelerationJacobians<Model, Scalar>) {
      value.resize(rows(x.size()));
      model_.acceleration(x, u, value);
      model_.acceleration_jacobians(x, u, gx, gu);
    } else if constexpr (!kSecondOrder && HasDerivativeJacobians<Model, Scalar>) {
      value.resize(rows(x.size()));
      model_.derivative(x, u, value);
      model_.derivative_jacobians(x, u, gx, gu);
    } else {
      auto g = [this](const auto& xd, const auto& ud, auto& out) {
        this->evaluate(xd, ud, out);
      };
      automatic_jacobians<Scalar>(g, x, u, rows(x.size()), value, gx, gu);
    }
  }

  /// ẋ = f(x, u) in any scalar; for a second-order model f = (v, a) in its layout.
  template <class X, class U, class Out>
  void derivative(const X& x, const U& u, Out& xdot) const {
    if constexpr (kSecondOrder) {
      const Index n = x.size();
      ColumnOf<typename X::Scalar, kRhsSize> acc(n / 2);
      model_.acceleration(x, u, acc);
      for (Index i = 0; i < n / 2; ++i) {
        xdot(position(i, n)) = x(velocity(i, n));
        xdot(velocity(i, n)) = acc(i);
      }
    } else {
      model_.derivative(x, u, xdot);
    }
  }

  /// xdot = f(x, u), fx = ∂f/∂x (N × N), fu = ∂f/∂u (N × K).
  void derivative_with_jacobians(const State& x, const Control& u, State& xdot,
                                 Eigen::Matrix<Scalar, kStateSize, kStateSize>& fx,
                                 Eigen::Matrix<Scalar, kStateSize, kControlSize>& fu) const {
    if constexpr (kSecondOrder) {
      const Index n = x.size();
      Rhs acc;
      RhsByState ax;
      RhsByControl au;
      evaluate_with_jacobians(x, u, acc, ax, au);
      xdot.resize(n);
      fx.setZero(n, n);
      fu.setZero(n, u.size());
      for (Index i = 0; i < n / 2; ++i) {
        xdot(position(i, n)) = x(velocity(i, n));
        fx(position(i, n), velocity(i, n)) = Scalar(1);
        xdot(velocity(i, n)) = acc(i);
        fx.row(velocity(i, n)) = ax.row(i);
        fu.row(velocity(i, n)) = au.row(i);
      }
    } else {
      evaluate_with_jacobians(x, u, xdot, fx, fu);
    }
  }

private:
  const Model& model_;
};

}  // namespace detail

/// The `Simulator` x_{n+1} = Φ_h(x_n, u_n) of a continuous model and an integrator `Method`
/// (`ExplicitEuler`, `SemiImplicitEuler`, `Heun`, `RungeKutta4`); see the file comment for the
/// maps and their derivatives. Immutable and thread-safe when the model is.
template <class Model, class Method, class ScalarT = double>
class Integrated {
  static_assert(detail::HasModelSizes<Model>,
                "sbptt::Integrated: the model needs `static constexpr int kStateSize` and "
                "`kControlSize` (Eigen::Dynamic allowed)");
  static_assert(!detail::HasModelSizes<Model> || detail::IsFirstOrder<Model> ||
                    detail::IsSecondOrder<Model>,
                "sbptt::Integrated: the model needs `template <class T> void derivative(const "
                "ColumnOf<T, N>& x, const ColumnOf<T, K>& u, ColumnOf<T, N>& xdot) const` or, "
                "for a second-order model, `template <class T> void acceleration(const "
                "ColumnOf<T, N>& x, const ColumnOf<T, K>& u, ColumnOf<T, N/2>& a) const` "
                "(N = kStateSize, K = kControlSize)");
  static_assert(!detail::IsSecondOrder<Model> || !detail::has_odd_fixed_state_size<Model>(),
                "sbptt::Integrated: a second-order model's state is (q, v), two halves of one "
                "size: its kStateSize must be even");
  static_assert(!std::same_as<Method, SemiImplicitEuler> || detail::IsSecondOrder<Model>,
                "sbptt::Integrated: SemiImplicitEuler needs a second-order model (a templated "
                "`acceleration(x, u, a)`)");
  static_assert(!detail::HasModelSizes<Model> ||
                    !(detail::IsFirstOrder<Model> || detail::IsSecondOrder<Model>) ||
                    detail::HasRightHandSideJacobians<Model, ScalarT>,
                "sbptt::Integrated: without hand-written Jacobians the model's derivative (or "
                "acceleration) must be a template on the scalar (it is called with "
                "automatic-differentiation numbers): `template <class T> void derivative(const "
                "ColumnOf<T, N>& x, const ColumnOf<T, K>& u, ColumnOf<T, N>& xdot) const`");
  // Hand-written Jacobians that cannot be called, or of the other kind of model, would be
  // replaced by automatic ones without a word, and never run.
  static_assert(!detail::IsSecondOrder<Model> || !detail::NamesDerivativeJacobians<Model>,
                "sbptt::Integrated: a second-order model (with `acceleration`) gives "
                "acceleration_jacobians, not derivative_jacobians, which would never run");
  static_assert(detail::IsSecondOrder<Model> || !detail::NamesAccelerationJacobians<Model>,
                "sbptt::Integrated: a first-order model (with `derivative`, no `acceleration`) "
                "gives derivative_jacobians, not acceleration_jacobians, which would never run");
  static_assert(!detail::NamesDerivativeJacobians<Model> || detail::IsSecondOrder<Model> ||
                    detail::HasDerivativeJacobians<Model, ScalarT>,
                "sbptt::Integrated: the model's derivative_jacobians must be callable as `void "
                "derivative_jacobians(const ColumnOf<Scalar, N>& x, const ColumnOf<Scalar, K>& u, "
                "Eigen::Matrix<Scalar, N, N>& fx, Eigen::Matrix<Scalar, N, K>& fu) const` "
                "(N = kStateSize, K = kControlSize, Scalar = the Integrated's scalar)");
  static_assert(!detail::NamesAccelerationJacobians<Model> || !detail::IsSecondOrder<Model> ||
                    detail::HasAccelerationJacobians<Model, ScalarT>,
                "sbptt::Integrated: the model's acceleration_jacobians must be callable as `void "
                "acceleration_jacobians(const ColumnOf<Scalar, N>& x, const ColumnOf<Scalar, K>& "
                "u, Eigen::Matrix<Scalar, N/2, N>& ax, Eigen::Matrix<Scalar, N/2, K>& au) const` "
                "(N = kStateSize, K = kControlSize, Scalar = the Integrated's scalar)");
  using Rhs = detail::RightHandSide<Model, ScalarT>;

public:
  using Scalar = ScalarT;
  static constexpr int kStateSize = Model::kStateSize;
  static constexpr int kControlSize = Model::kControlSize;
  using State = ColumnOf<Scalar, kStateSize>;
  using Control = ColumnOf<Scalar, kControlSize>;
  using StateJacobian = Eigen::Matrix<Scalar, kStateSize, kStateSize>;
  using ControlJacobian = Eigen::Matrix<Scalar, kStateSize, kControlSize>;

  /// \param dt the time step h (finite, > 0). Throws InvalidArgument on a bad step or sizes
  ///        (a second-order model needs an even state size).
  Integrated(Model model, Scalar dt) : model_(std::move(model)), dt_(dt) {
    detail::check_model_sizes(model_, "Integrated");
    detail::require(std::isfinite(dt) && dt > 0, "Integrated: dt = ", dt,
                    "; expected a finite time step > 0");
    detail::require(!Rhs::kSecondOrder || state_dim() % 2 == 0, "Integrated: state_dim() = ",
                    state_dim(), " for a second-order model; expected an even size (q, v)");
  }

  [[nodiscard]] const Model& model() const { return model_; }
  [[nodiscard]] Index state_dim() const { return detail::model_state_dim(model_); }
  [[nodiscard]] Index control_dim() const { return detail::model_control_dim(model_); }
  [[nodiscard]] Scalar dt() const { return dt_; }

  /// x_next = Φ_h(x, u). x, x_next: state_dim; u: control_dim. `x_next` may alias `x`.
  void step(const State& x, const Control& u, State& x_next) const {
    check_sizes(x, u);
    const Rhs rhs(model_);
    const Index n = state_dim();
    if constexpr (std::same_as<Method, SemiImplicitEuler>) {
      typename Rhs::Rhs acc(n / 2);
      rhs.evaluate(x, u, acc);
      State out = x;
      for (Index i = 0; i < n / 2; ++i) {
        const Index q = Rhs::position(i, n), v = Rhs::velocity(i, n);
        out(v) = x(v) + dt_ * acc(i);
        out(q) = x(q) + dt_ * out(v);
      }
      x_next = out;
    } else {
      std::array<State, Method::kStages> k;
      State stage(n), sum = State::Zero(n);
      for (int i = 0; i < Method::kStages; ++i) {
        stage = x;
        for (int j = 0; j < i; ++j)
          if (Method::a(i, j) != 0.0) stage += (dt_ * coefficient(Method::a(i, j))) * k[idx(j)];
        k[idx(i)].resize(n);
        rhs.derivative(stage, u, k[idx(i)]);
        sum += coefficient(Method::b[idx(i)]) * k[idx(i)];
      }
      x_next = x + dt_ * sum;
    }
  }

  /// A = ∂x_next/∂x (state_dim × state_dim), B = ∂x_next/∂u (state_dim × control_dim), exact
  /// for the discrete map.
  void jacobians(const State& x, const Control& u, StateJacobian& a, ControlJacobian& b) const {
    check_sizes(x, u);
    const Rhs rhs(model_);
    const Index n = state_dim(), m = control_dim();
    if constexpr (std::same_as<Method, SemiImplicitEuler>) {
      typename Rhs::Rhs acc;
      typename Rhs::RhsByState ax;
      typename Rhs::RhsByControl au;
      rhs.evaluate_with_jacobians(x, u, acc, ax, au);
      a.setIdentity(n, n);
      b.setZero(n, m);
      for (Index i = 0; i < n / 2; ++i) {
        const Index q = Rhs::position(i, n), v = Rhs::velocity(i, n);
        a.row(v) += dt_ * ax.row(i);
        b.row(v) = dt_ * au.row(i);
        a.row(q) += dt_ * a.row(v);
        b.row(q) = dt_ * b.row(v);
      }
    } else {
      std::array<State, Method::kStages> k;
      std::array<StateJacobian, Method::kStages> kx;
      std::array<ControlJacobian, Method::kStages> ku;
      State stage(n);
      StateJacobian stage_x(n, n), fx;
      ControlJacobian stage_u(n, m), fu;
      a.setIdentity(n, n);
      b.setZero(n, m);
      for (int i = 0; i < Method::kStages; ++i) {
        stage = x;
        stage_x.setIdentity();
        stage_u.setZero();
        for (int j = 0; j < i; ++j) {
          if (Method::a(i, j) == 0.0) continue;
          const Scalar w = dt_ * coefficient(Method::a(i, j));
          stage += w * k[idx(j)];
          stage_x += w * kx[idx(j)];
          stage_u += w * ku[idx(j)];
        }
        rhs.derivative_with_jacobians(stage, u, k[idx(i)], fx, fu);
        kx[idx(i)].noalias() = fx * stage_x;
        ku[idx(i)] = fu;
        ku[idx(i)].noalias() += fx * stage_u;
        const Scalar w = dt_ * coefficient(Method::b[idx(i)]);
        a += w * kx[idx(i)];
        b += w * ku[idx(i)];
      }
    }
  }

  /// *lambda_x = Aᵀλ (state_dim), *lambda_u = Bᵀλ (control_dim), by the reverse sweep over
  /// the stages (never forming A). A null pointer skips that product.
  void vjp(const State& x, const Control& u, const State& lambda, State* lambda_x,
           Control* lambda_u) const {
    detail::check_vjp_sizes(*this, x, u, lambda, "Integrated");
    if (lambda_x == nullptr && lambda_u == nullptr) return;
    const Rhs rhs(model_);
    const Index n = state_dim(), m = control_dim();
    if constexpr (std::same_as<Method, SemiImplicitEuler>) {
      typename Rhs::Rhs acc, acc_adj(n / 2);
      typename Rhs::RhsByState ax;
      typename Rhs::RhsByControl au;
      rhs.evaluate_with_jacobians(x, u, acc, ax, au);
      State direct(n);
      for (Index i = 0; i < n / 2; ++i) {
        const Index q = Rhs::position(i, n), v = Rhs::velocity(i, n);
        const Scalar velocity_adj = lambda(v) + dt_ * lambda(q);  // adjoint of v'
        direct(q) = lambda(q);
        direct(v) = velocity_adj;
        acc_adj(i) = dt_ * velocity_adj;
      }
      if (lambda_x != nullptr) {
        *lambda_x = direct;
        lambda_x->noalias() += ax.transpose() * acc_adj;
      }
      if (lambda_u != nullptr) lambda_u->noalias() = au.transpose() * acc_adj;
    } else {
      std::array<State, Method::kStages> k, stage_adj;
      std::array<StateJacobian, Method::kStages> fx;
      std::array<ControlJacobian, Method::kStages> fu;
      State stage(n), k_adj(n);
      for (int i = 0; i < Method::kStages; ++i) {
        stage = x;
        for (int j = 0; j < i; ++j)
          if (Method::a(i, j) != 0.0) stage += (dt_ * coefficient(Method::a(i, j))) * k[idx(j)];
        rhs.derivative_with_jacobians(stage, u, k[idx(i)], fx[idx(i)], fu[idx(i)]);
      }
      State x_adj = lambda;
      Control u_adj = Control::Zero(m);
      for (int i = Method::kStages - 1; i >= 0; --i) {
        k_adj = (dt_ * coefficient(Method::b[idx(i)])) * lambda;
        for (int j = i + 1; j < Method::kStages; ++j)
          if (Method::a(j, i) != 0.0)
            k_adj += (dt_ * coefficient(Method::a(j, i))) * stage_adj[idx(j)];
        stage_adj[idx(i)].noalias() = fx[idx(i)].transpose() * k_adj;
        x_adj += stage_adj[idx(i)];
        u_adj.noalias() += fu[idx(i)].transpose() * k_adj;
      }
      if (lambda_x != nullptr) *lambda_x = x_adj;
      if (lambda_u != nullptr) *lambda_u = u_adj;
    }
  }

private:
  static constexpr std::size_t idx(int i) { return static_cast<std::size_t>(i); }
  static Scalar coefficient(double c) { return static_cast<Scalar>(c); }

  void check_sizes(const State& x, const Control& u) const {
    detail::check_input_sizes(*this, x, u, "Integrated");
  }

  Model model_;
  Scalar dt_;
};

}  // namespace sbptt
