#pragma once
/// \file Linear time-invariant system, the analytic test bed of the engine.
///
///     x_{n+1} = A x_n + B u_n          A: d × d,  B: d × k
///
/// State layout: the d entries of x. Control layout: the k entries of u.
/// With A = B = 1 (d = k = 1) this is the paper's toy problem P(x, c) = x + c (Fig. 1); with a
/// linear policy u = θ x it is the LQR setting an ICLR reviewer asked about.
#include <cmath>

#include "sbptt/core/concepts.hpp"
#include "sbptt/core/error.hpp"
#include "sbptt/sim/input_sizes.hpp"

namespace sbptt {

/// x' = A x + B u with constant A (StateDim × StateDim) and B (StateDim × ControlDim).
template <class ScalarT = double, int StateDim = Eigen::Dynamic, int ControlDim = Eigen::Dynamic>
class LinearSystem {
public:
  using Scalar = ScalarT;
  using State = Eigen::Matrix<Scalar, StateDim, 1>;
  using Control = Eigen::Matrix<Scalar, ControlDim, 1>;
  using StateJacobian = Eigen::Matrix<Scalar, StateDim, StateDim>;
  using ControlJacobian = Eigen::Matrix<Scalar, StateDim, ControlDim>;

  /// \param a (d × d), \param b (d × k), \param dt reported time step (> 0; not used by the map).
  LinearSystem(StateJacobian a, ControlJacobian b, Scalar dt = Scalar(1))
      : a_(std::move(a)), b_(std::move(b)), dt_(dt) {
    detail::require(a_.rows() == a_.cols() && a_.rows() > 0, "LinearSystem: A is ", a_.rows(),
                    " x ", a_.cols(), "; expected a non-empty square matrix");
    detail::require(b_.rows() == a_.rows() && b_.cols() > 0, "LinearSystem: B is ", b_.rows(),
                    " x ", b_.cols(), "; expected ", a_.rows(), " rows and at least one column");
    detail::require(a_.allFinite() && b_.allFinite(),
                    "LinearSystem: A or B has a non-finite entry; expected finite matrices");
    detail::require(std::isfinite(dt_) && dt_ > 0, "LinearSystem: dt = ", dt_,
                    "; expected a finite number > 0");
  }

  /// The scalar system x' = a x + b u.
  static LinearSystem scalar(Scalar a, Scalar b) {
    StateJacobian am(1, 1);
    ControlJacobian bm(1, 1);
    am(0, 0) = a;
    bm(0, 0) = b;
    return LinearSystem(am, bm);
  }

  [[nodiscard]] Index state_dim() const { return a_.rows(); }
  [[nodiscard]] Index control_dim() const { return b_.cols(); }
  [[nodiscard]] Scalar dt() const { return dt_; }

  void step(const State& x, const Control& u, State& x_next) const {
    detail::check_input_sizes(*this, x, u, "LinearSystem");
    x_next.noalias() = a_ * x;
    x_next.noalias() += b_ * u;
  }

  void jacobians(const State& x, const Control& u, StateJacobian& a, ControlJacobian& b) const {
    detail::check_input_sizes(*this, x, u, "LinearSystem");
    a = a_;
    b = b_;
  }

  void vjp(const State& x, const Control& u, const State& lambda, State* lambda_x,
           Control* lambda_u) const {
    detail::check_vjp_sizes(*this, x, u, lambda, "LinearSystem");
    if (lambda_x) lambda_x->noalias() = a_.transpose() * lambda;
    if (lambda_u) lambda_u->noalias() = b_.transpose() * lambda;
  }

private:
  StateJacobian a_;
  ControlJacobian b_;
  Scalar dt_;
};

static_assert(Simulator<LinearSystem<double>>);
static_assert(Simulator<LinearSystem<float, 1, 1>>);

}  // namespace sbptt
