#pragma once
// A user-defined controller, written against the Controller concept only (no sbptt::nn):
// the linear state feedback u = −K x of linear-quadratic control, K of size k × d stored
// row-major in the flat parameter vector (as a bias-free dense layer stores its weight).
// Used by the LQR convergence study and its test.
#include "sbptt/core/concepts.hpp"
#include "sbptt/core/error.hpp"

namespace sbptt::testing {

template <class ScalarT>
class LinearFeedback {
public:
  using Scalar = ScalarT;
  struct Workspace {
    Matrix<Scalar> inputs;  ///< d × batch
  };
  using GainMatrix = RowMajorMatrix<Scalar>;

  /// u = −K x with K = 0, for states of `states` entries and controls of `controls` entries.
  LinearFeedback(Index states, Index controls)
      : states_(states), controls_(controls), params_(Vector<Scalar>::Zero(states * controls)) {
    detail::require(states > 0 && controls > 0, "LinearFeedback: ", controls, " x ", states,
                    " gain; expected at least one state and one control");
  }

  [[nodiscard]] Index input_dim() const { return states_; }
  [[nodiscard]] Index output_dim() const { return controls_; }
  [[nodiscard]] Index num_params() const { return params_.size(); }
  [[nodiscard]] const Vector<Scalar>& params() const { return params_; }
  [[nodiscard]] Vector<Scalar>& params() { return params_; }

  /// The gain K (k × d), a view of the parameters.
  [[nodiscard]] Eigen::Map<const GainMatrix> gain() const {
    return {params_.data(), controls_, states_};
  }
  [[nodiscard]] Eigen::Map<GainMatrix> gain() { return {params_.data(), controls_, states_}; }

  /// \param x states (d × batch) \param y controls (k × batch)
  void forward(const Matrix<Scalar>& x, Matrix<Scalar>& y, Workspace& ws) const {
    ws.inputs = x;
    y.noalias() = -(gain() * x);
  }

  /// grad += ∂(Σ dyᵀu)/∂K = −dy xᵀ (row-major); dx = −Kᵀ dy when asked for.
  void backward(const Workspace& ws, const Matrix<Scalar>& dy, Vector<Scalar>& grad,
                Matrix<Scalar>* dx) const {
    Eigen::Map<GainMatrix>(grad.data(), controls_, states_).noalias() -= dy * ws.inputs.transpose();
    if (dx) dx->noalias() = -(gain().transpose() * dy);
  }

private:
  Index states_, controls_;
  Vector<Scalar> params_;
};

static_assert(Controller<LinearFeedback<double>>);
static_assert(Controller<LinearFeedback<float>>);

}  // namespace sbptt::testing
