#pragma once
/// \file Stochastic gradient descent with optional heavy-ball momentum.
///
/// With μ = momentum and g the incoming vector (size n):
///
///     μ = 0:   θ ← θ − lr · g
///     μ > 0:   u ← μ u + g,   θ ← θ − lr · u      (u = 0 before the first step)
///
/// This is PyTorch's `SGD(momentum=μ, dampening=0, nesterov=False)`. Keras keeps the velocity
/// in parameter units instead, w ← μ w − lr g, θ ← θ + w, so w = −lr · u: the iterates are
/// identical while lr is constant, and differ only after a learning-rate change (here the new
/// lr also scales the accumulated velocity, in Keras it does not). The reference's
/// `training.py` offers SGD with momentum 0.8/0.9/0.95 but its run scripts use only Adam.
#include <cmath>
#include <concepts>

#include "sbptt/core/error.hpp"
#include "sbptt/core/types.hpp"
#include "sbptt/optim/step_checks.hpp"

namespace sbptt {

/// Hyper-parameters of `Sgd`; the defaults are Keras's.
template <std::floating_point Scalar = double>
struct SgdOptions {
  Scalar learning_rate = Scalar(0.01);  ///< lr > 0, finite
  Scalar momentum = Scalar(0);          ///< μ in [0, 1); 0 = plain gradient descent
};

/// Gradient descent on a flat parameter vector (see the file comment for the momentum form).
template <std::floating_point S = double>
class Sgd {
public:
  using Scalar = S;
  using Options = SgdOptions<Scalar>;

  Sgd() : Sgd(Options{}) {}

  /// Throws `InvalidArgument` naming the first option out of range.
  explicit Sgd(const Options& options) : options_(options) {
    detail::require_learning_rate(options_.learning_rate, "Sgd");
    detail::require_decay(options_.momentum, "Sgd", "momentum");
  }

  /// One update of `params` (size n) with `grad` (size n).
  void step(Vector<Scalar>& params, const Vector<Scalar>& grad) {
    const bool uses_velocity = options_.momentum > Scalar(0);
    detail::require_step_sizes(params, grad, velocity_.size(), uses_velocity && iterations_ > 0,
                               "Sgd::step");
    if (uses_velocity) {
      if (iterations_ == 0) velocity_.setZero(params.size());
      velocity_ = options_.momentum * velocity_ + grad;
      params -= options_.learning_rate * velocity_;
    } else {
      params -= options_.learning_rate * grad;
    }
    ++iterations_;
  }

  /// Number of steps taken since construction or `reset()`.
  [[nodiscard]] Index iterations() const { return iterations_; }

  /// Forgets the velocity and the step count.
  void reset() {
    iterations_ = 0;
    velocity_.resize(0);
  }

  [[nodiscard]] const Options& options() const { return options_; }

  /// For schedules: changes lr from the next step on, keeping the velocity.
  void set_learning_rate(Scalar learning_rate) {
    detail::require_learning_rate(learning_rate, "Sgd::set_learning_rate");
    options_.learning_rate = learning_rate;
  }

  /// u in gradient units (size n after the first step with momentum, empty otherwise).
  [[nodiscard]] const Vector<Scalar>& velocity() const { return velocity_; }

private:
  Options options_;
  Vector<Scalar> velocity_;
  Index iterations_ = 0;
};

}  // namespace sbptt
