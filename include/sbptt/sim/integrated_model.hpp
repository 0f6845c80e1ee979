#pragma once
/// \file What `Integrated` (integrators.hpp) asks of a model, as concepts: a first- or
/// second-order right-hand side, and hand-written Jacobians callable as that header's file
/// comment says, or else a right-hand side it can differentiate automatically. Implementation
/// detail of `Integrated`, whose static_asserts turn each unmet concept into a message.
#include <type_traits>

#include <Eigen/Core>

#include "sbptt/core/types.hpp"
#include "sbptt/sim/autodiff.hpp"

namespace sbptt::detail {

constexpr int half_or_dynamic(int n) { return n == Eigen::Dynamic ? Eigen::Dynamic : n / 2; }

/// The model declares a fixed, odd kStateSize (false without one: a static_assert that named
/// kStateSize would add its own errors to the message for a model that lacks it).
template <class M>
constexpr bool has_odd_fixed_state_size() {
  if constexpr (requires { M::kStateSize; }) {
    return M::kStateSize != Eigen::Dynamic && M::kStateSize % 2 != 0;
  } else {
    return false;
  }
}

/// A model with a templated `acceleration(x, u, a)` (tested at double).
template <class M>
concept IsSecondOrder = requires(const M& m, const ColumnOf<double, M::kStateSize>& x,
                                 const ColumnOf<double, M::kControlSize>& u,
                                 ColumnOf<double, half_or_dynamic(M::kStateSize)>& a) {
  m.acceleration(x, u, a);
};

/// A model with a templated `derivative(x, u, xdot)` (tested at double).
template <class M>
concept IsFirstOrder = requires(const M& m, const ColumnOf<double, M::kStateSize>& x,
                                const ColumnOf<double, M::kControlSize>& u,
                                ColumnOf<double, M::kStateSize>& xdot) {
  m.derivative(x, u, xdot);
};

/// Hand-written Jacobians callable as the file comment says, in `Scalar`.
template <class M, class Scalar>
concept HasDerivativeJacobians =
    requires(const M& m, const ColumnOf<Scalar, M::kStateSize>& x,
             const ColumnOf<Scalar, M::kControlSize>& u,
             Eigen::Matrix<Scalar, M::kStateSize, M::kStateSize>& fx,
             Eigen::Matrix<Scalar, M::kStateSize, M::kControlSize>& fu) {
      m.derivative_jacobians(x, u, fx, fu);
    };
template <class M, class Scalar>
concept HasAccelerationJacobians =
    requires(const M& m, const ColumnOf<Scalar, M::kStateSize>& x,
             const ColumnOf<Scalar, M::kControlSize>& u,
             Eigen::Matrix<Scalar, half_or_dynamic(M::kStateSize), M::kStateSize>& ax,
             Eigen::Matrix<Scalar, half_or_dynamic(M::kStateSize), M::kControlSize>& au) {
      m.acceleration_jacobians(x, u, ax, au);
    };

// A member of any kind and signature (a template, an overload set, one that is not callable)
// is found by its name alone: beside `JacobianNames`, the name is ambiguous in
// `WithJacobianNames<M>`. A final model cannot be derived from; only a plain member function
// of it is found.
struct JacobianNames {
  int derivative_jacobians, acceleration_jacobians;
};
template <class M>
struct WithJacobianNames : M, JacobianNames {};
template <class M>
concept Inheritable = std::is_class_v<M> && !std::is_final_v<M>;
template <class M>
concept NamesDerivativeJacobians =
    (Inheritable<M> && !requires { &WithJacobianNames<M>::derivative_jacobians; }) ||
    (!Inheritable<M> && requires { &M::derivative_jacobians; });
template <class M>
concept NamesAccelerationJacobians =
    (Inheritable<M> && !requires { &WithJacobianNames<M>::acceleration_jacobians; }) ||
    (!Inheritable<M> && requires { &M::acceleration_jacobians; });

// The dual numbers of automatic Jacobians (autodiff.hpp) are what f (or a) is called with.
template <class M, class Scalar>
concept DerivativeInDualNumbers =
    requires(const M& m, const DualColumnOf<M, Scalar, M::kStateSize>& x,
             const DualColumnOf<M, Scalar, M::kControlSize>& u,
             DualColumnOf<M, Scalar, M::kStateSize>& xdot) { m.derivative(x, u, xdot); };
template <class M, class Scalar>
concept AccelerationInDualNumbers =
    requires(const M& m, const DualColumnOf<M, Scalar, M::kStateSize>& x,
             const DualColumnOf<M, Scalar, M::kControlSize>& u,
             DualColumnOf<M, Scalar, half_or_dynamic(M::kStateSize)>& a) {
      m.acceleration(x, u, a);
    };
/// f's (or a's) Jacobians can be had: by hand, or automatically from a templated f (or a).
template <class M, class Scalar>
concept HasRightHandSideJacobians =
    (IsSecondOrder<M> && (HasAccelerationJacobians<M, Scalar> ||
                          AccelerationInDualNumbers<M, Scalar>)) ||
    (!IsSecondOrder<M> && (HasDerivativeJacobians<M, Scalar> ||
                           DerivativeInDualNumbers<M, Scalar>));

}  // namespace sbptt::detail
