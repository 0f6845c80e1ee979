#pragma once
/// \file Automatic Jacobians: a scene written once as a step templated on the scalar becomes a
/// full `Simulator` (step, jacobians, vjp), through Eigen's forward-mode `AutoDiffScalar`.
///
/// A model is
///
///     struct Scene {
///       static constexpr int kStateSize = 4, kControlSize = 1;   // or Eigen::Dynamic
///       template <class T>
///       void step(const Eigen::Matrix<T, 4, 1>& x, const Eigen::Matrix<T, 1, 1>& u,
///                 Eigen::Matrix<T, 4, 1>& x_next) const;
///     };
///
/// plus `Index state_dim() const` and `Index control_dim() const` when a size is dynamic.
/// `AutoDiffSimulator<Scene>` calls `step` with T = Scalar for the value and with
/// T = AutoDiffScalar<Eigen::Matrix<Scalar, N + K, 1>> for the derivatives.
///
/// Cost model: one evaluation of the step in dual numbers carries N + K derivative directions
/// (N = state_dim, K = control_dim) and yields the whole [A B] at once, so `jacobians` and
/// `vjp` each cost about (N + K) plain steps (plus the Aᵀλ product for `vjp`). With fixed N
/// and K the derivative vectors live on the stack (no allocation, vectorised); with a dynamic
/// size every dual number allocates. A hand-written VJP pays off when N is large and the
/// Jacobian is structured (the cart pole's is O(P) instead of O(P²), Schrödinger's is a
/// tridiagonal solve instead of N solves), or when the step dominates the training epoch.
///
/// Everything Eigen offers on a scalar type works inside the step: sin, cos, sqrt, exp,
/// comparisons (on the value), and dense solves, e.g. `M.ldlt().solve(rhs)` or
/// `M.partialPivLu().solve(rhs)` for a mass matrix M(q) of a Lagrangian system.
/// A part whose slope is infinite at a point gives NaN there even inside a smooth whole
/// (|v| v at v = 0 written with sqrt or norm: ∞ · 0): branch on the value or smooth the term
/// (docs/scenes.md).
/// Constants in a step that must also compile in float are written `constant<T>(0.5)`: a
/// `double` times a float dual number is a narrowing conversion.
#include <concepts>
#include <utility>

#include <Eigen/Core>
#include <unsupported/Eigen/AutoDiff>

#include "sbptt/core/error.hpp"
#include "sbptt/core/types.hpp"
#include "sbptt/sim/input_sizes.hpp"

namespace sbptt {

/// Eigen column vector of `T` with `Size` entries (`Eigen::Dynamic` allowed).
template <class T, int Size>
using ColumnOf = Eigen::Matrix<T, Size, 1>;

/// A forward-mode dual number of `Scalar` with `Directions` derivative directions.
template <class Scalar, int Directions>
using Dual = Eigen::AutoDiffScalar<ColumnOf<Scalar, Directions>>;

/// Derivative directions of a map of N states and K controls: N + K, or dynamic.
constexpr int sum_or_dynamic(int n, int k) {
  return n == Eigen::Dynamic || k == Eigen::Dynamic ? Eigen::Dynamic : n + k;
}

namespace detail {
template <class T>
struct PlainScalarOf {
  using Type = T;
};
template <class Derivatives>
struct PlainScalarOf<Eigen::AutoDiffScalar<Derivatives>> {
  using Type = typename Eigen::AutoDiffScalar<Derivatives>::Real;
};
}  // namespace detail

/// `value` as a constant of the scalar `T` of a templated step (double, float or a dual number
/// of either), rounded once to T's precision: `constant<T>(dt)` compiles without a narrowing
/// warning where `T(dt)` would narrow a double to float.
template <class T>
[[nodiscard]] T constant(double value) {
  return T(static_cast<typename detail::PlainScalarOf<T>::Type>(value));
}

namespace detail {

template <class M>
concept HasModelSizes = requires {
  { M::kStateSize } -> std::convertible_to<int>;
  { M::kControlSize } -> std::convertible_to<int>;
};

/// The model's run-time sizes: its members when it has them, else the compile-time sizes.
template <class M>
Index model_state_dim(const M& model) {
  if constexpr (requires { model.state_dim(); }) {
    return static_cast<Index>(model.state_dim());
  } else {
    static_assert(M::kStateSize != Eigen::Dynamic,
                  "sbptt: a model with kStateSize = Eigen::Dynamic needs `Index state_dim() const`");
    return M::kStateSize;
  }
}
template <class M>
Index model_control_dim(const M& model) {
  if constexpr (requires { model.control_dim(); }) {
    return static_cast<Index>(model.control_dim());
  } else {
    static_assert(M::kControlSize != Eigen::Dynamic, "sbptt: a model with kControlSize = "
                                                     "Eigen::Dynamic needs `Index control_dim() const`");
    return M::kControlSize;
  }
}

/// A column of the dual numbers `AutoDiffSimulator<M, Scalar>` calls the model's step with.
template <class M, class Scalar, int Size>
using DualColumnOf = ColumnOf<Dual<Scalar, sum_or_dynamic(M::kStateSize, M::kControlSize)>, Size>;

template <class M, class Scalar>
concept StepsInDualNumbers = requires(const M& m,
                                      const DualColumnOf<M, Scalar, M::kStateSize>& x,
                                      const DualColumnOf<M, Scalar, M::kControlSize>& u,
                                      DualColumnOf<M, Scalar, M::kStateSize>& x_next) {
  m.step(x, u, x_next);
};

/// Requires the model's run-time sizes to be positive and to match its compile-time ones.
template <class M>
void check_model_sizes(const M& model, const char* who) {
  const Index n = model_state_dim(model), k = model_control_dim(model);
  require(n > 0 && (M::kStateSize == Eigen::Dynamic || n == M::kStateSize), who,
          ": the model's state_dim() = ", n, "; expected a positive size equal to kStateSize = ",
          M::kStateSize, " (-1 means dynamic)");
  require(k > 0 && (M::kControlSize == Eigen::Dynamic || k == M::kControlSize), who,
          ": the model's control_dim() = ", k,
          "; expected a positive size equal to kControlSize = ", M::kControlSize,
          " (-1 means dynamic)");
}

}  // namespace detail

/// Value and Jacobians of r = g(x, u) by one forward-mode pass with N + K directions.
///
/// `g(x, u, r)` is a generic callable writing `r` (`rows` entries) from dual vectors x (N) and
/// u (K). Sets `value` (rows), `jx = ∂r/∂x` (rows × N) and `ju = ∂r/∂u` (rows × K). An output
/// that does not depend on the inputs (a dual built from a constant) gets zero derivatives.
template <class Scalar, int N, int K, int R, class G>
void automatic_jacobians(const G& g, const ColumnOf<Scalar, N>& x, const ColumnOf<Scalar, K>& u,
                         Index rows, ColumnOf<Scalar, R>& value,
                         Eigen::Matrix<Scalar, R, N>& jx, Eigen::Matrix<Scalar, R, K>& ju) {
  constexpr int directions_at_compile_time = sum_or_dynamic(N, K);
  using D = Dual<Scalar, directions_at_compile_time>;
  const Index n = x.size(), k = u.size(), directions = n + k;
  ColumnOf<D, N> xd(n);
  ColumnOf<D, K> ud(k);
  ColumnOf<D, R> rd(rows);
  using Derivatives = ColumnOf<Scalar, directions_at_compile_time>;
  for (Index i = 0; i < n; ++i) xd(i) = D(x(i), Derivatives::Unit(directions, i));
  for (Index j = 0; j < k; ++j) ud(j) = D(u(j), Derivatives::Unit(directions, n + j));
  g(xd, ud, rd);
  value.resize(rows);
  jx.resize(rows, n);
  ju.resize(rows, k);
  for (Index r = 0; r < rows; ++r) {
    value(r) = rd(r).value();
    const auto& d = rd(r).derivatives();
    if (d.size() == directions) {
      jx.row(r) = d.head(n).transpose();
      ju.row(r) = d.tail(k).transpose();
    } else {
      jx.row(r).setZero();
      ju.row(r).setZero();
    }
  }
}

/// A `Simulator` from a model that only writes its step, templated on the scalar (see the file
/// comment). Immutable and thread-safe when the model's step is.
template <class Model, class ScalarT = double>
class AutoDiffSimulator {
  static_assert(detail::HasModelSizes<Model>,
                "sbptt::AutoDiffSimulator: the model needs `static constexpr int kStateSize` and "
                "`kControlSize` (Eigen::Dynamic allowed)");
  static_assert(!detail::HasModelSizes<Model> || detail::StepsInDualNumbers<Model, ScalarT>,
                "sbptt::AutoDiffSimulator: the model's step must be a template on the scalar "
                "(it is called with automatic-differentiation numbers): `template <class T> "
                "void step(const ColumnOf<T, N>& x, const ColumnOf<T, K>& u, ColumnOf<T, N>& "
                "x_next) const` (N = kStateSize, K = kControlSize)");

public:
  using Scalar = ScalarT;
  static constexpr int kStateSize = Model::kStateSize;
  static constexpr int kControlSize = Model::kControlSize;
  using State = ColumnOf<Scalar, kStateSize>;
  using Control = ColumnOf<Scalar, kControlSize>;
  using StateJacobian = Eigen::Matrix<Scalar, kStateSize, kStateSize>;
  using ControlJacobian = Eigen::Matrix<Scalar, kStateSize, kControlSize>;

  /// Throws InvalidArgument when the model's sizes are not positive or disagree with its
  /// compile-time sizes.
  explicit AutoDiffSimulator(Model model = {}) : model_(std::move(model)) {
    detail::check_model_sizes(model_, "AutoDiffSimulator");
  }

  [[nodiscard]] const Model& model() const { return model_; }
  [[nodiscard]] Index state_dim() const { return detail::model_state_dim(model_); }
  [[nodiscard]] Index control_dim() const { return detail::model_control_dim(model_); }

  /// x_next = P(x, u) in plain `Scalar`. x, x_next: state_dim; u: control_dim.
  void step(const State& x, const Control& u, State& x_next) const {
    check_sizes(x, u);
    x_next.resize(state_dim());
    model_.step(x, u, x_next);
  }

  /// A = ∂x_next/∂x (state_dim × state_dim), B = ∂x_next/∂u (state_dim × control_dim).
  void jacobians(const State& x, const Control& u, StateJacobian& a, ControlJacobian& b) const {
    check_sizes(x, u);
    State value;
    automatic_jacobians<Scalar>(stepper(), x, u, state_dim(), value, a, b);
  }

  /// *lambda_x = Aᵀλ (state_dim), *lambda_u = Bᵀλ (control_dim); a null pointer skips it.
  void vjp(const State& x, const Control& u, const State& lambda, State* lambda_x,
           Control* lambda_u) const {
    detail::check_vjp_sizes(*this, x, u, lambda, "AutoDiffSimulator");
    if (lambda_x == nullptr && lambda_u == nullptr) return;
    State value;
    StateJacobian a;
    ControlJacobian b;
    automatic_jacobians<Scalar>(stepper(), x, u, state_dim(), value, a, b);
    if (lambda_x != nullptr) lambda_x->noalias() = a.transpose() * lambda;
    if (lambda_u != nullptr) lambda_u->noalias() = b.transpose() * lambda;
  }

private:
  [[nodiscard]] auto stepper() const {
    return [this](const auto& x, const auto& u, auto& x_next) { model_.step(x, u, x_next); };
  }

  void check_sizes(const State& x, const Control& u) const {
    detail::check_input_sizes(*this, x, u, "AutoDiffSimulator");
  }

  Model model_;
};

}  // namespace sbptt
