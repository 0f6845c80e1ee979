#pragma once
// A user-defined controller, written against the Controller concept only (no sbptt::nn),
// used by the toy program and the engine tests:
// the scalar policy c = Σ_k θ_k · x^{p_k}. Powers {1} give the linear policy c = θ x of the
// LQR test; powers {2, 1} give the paper's toy network c = θ1 x² + θ2 x.
#include <utility>
#include <vector>

#include "sbptt/core/concepts.hpp"

namespace sbptt::testing {

template <class ScalarT>
class PolynomialPolicy {
public:
  using Scalar = ScalarT;
  struct Workspace {
    Matrix<Scalar> inputs;
  };

  explicit PolynomialPolicy(std::vector<int> powers)
      : powers_(std::move(powers)), params_(Vector<Scalar>::Zero(static_cast<Index>(powers_.size()))) {}

  [[nodiscard]] Index input_dim() const { return 1; }
  [[nodiscard]] Index output_dim() const { return 1; }
  [[nodiscard]] Index num_params() const { return params_.size(); }
  [[nodiscard]] const Vector<Scalar>& params() const { return params_; }
  [[nodiscard]] Vector<Scalar>& params() { return params_; }

  void forward(const Matrix<Scalar>& x, Matrix<Scalar>& y, Workspace& ws) const {
    ws.inputs = x;
    y.setZero(1, x.cols());
    for (std::size_t k = 0; k < powers_.size(); ++k)
      y.array() += params_(static_cast<Index>(k)) * x.array().pow(static_cast<Scalar>(powers_[k]));
  }

  void backward(const Workspace& ws, const Matrix<Scalar>& dy, Vector<Scalar>& grad,
                Matrix<Scalar>* dx) const {
    const auto& x = ws.inputs;
    for (std::size_t k = 0; k < powers_.size(); ++k)
      grad(static_cast<Index>(k)) +=
          (dy.array() * x.array().pow(static_cast<Scalar>(powers_[k]))).sum();
    if (!dx) return;
    dx->setZero(1, x.cols());
    for (std::size_t k = 0; k < powers_.size(); ++k) {
      const auto p = static_cast<Scalar>(powers_[k]);
      dx->array() += dy.array() * params_(static_cast<Index>(k)) * p * x.array().pow(p - 1);
    }
  }

private:
  std::vector<int> powers_;
  Vector<Scalar> params_;
};

static_assert(Controller<PolynomialPolicy<double>>);

}  // namespace sbptt::testing
