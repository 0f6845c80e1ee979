#pragma once
/// \file Adam in the form the paper's reference ran: TF 2.9 legacy Keras `Adam`, which calls
/// the fused `ResourceApplyAdam` kernel.
///
/// With t counted from 1 and g the incoming vector (size n):
///
///     m ← β1 m + (1 − β1) g
///     v ← β2 v + (1 − β2) g²
///     α = lr · √(1 − β2^t) / (1 − β1^t)
///     θ ← θ − α · m / (√v + ε)
///
/// The bias correction is folded into the step size α and ε is added to the *un*-corrected
/// √v. PyTorch (and the Adam paper's Algorithm 1) instead compute
///
///     θ ← θ − lr/(1 − β1^t) · m / (√v / √(1 − β2^t) + ε)  =  θ − α · m / (√v + ε·√(1 − β2^t)),
///
/// i.e. they use a smaller effective ε, ε·√(1 − β2^t) (≈ 0.032 ε at t = 1, → ε as t → ∞).
/// The two agree while √v ≫ ε and differ when √v is of order ε or below: there the Keras step
/// is √(1 − β2^t) times the PyTorch one. That regime is not exotic here. The combined update
/// zeroes every component whose signs disagree, vanishing gradients are one of the paper's
/// two failure modes, and a component that has been (nearly) zero and then receives a tiny
/// value is damped by ε in this form where PyTorch would already take an O(lr) step. So a
/// reproduction must use this placement, and ε = 1e-7 (Keras) rather than 1e-8 (PyTorch).
///
/// The moment updates are evaluated as the kernel does, m += (g − m)(1 − β1), which equals the
/// formula above in exact arithmetic and keeps float results close to TF's.
#include <cmath>
#include <concepts>
#include <utility>

#include "sbptt/core/error.hpp"
#include "sbptt/core/types.hpp"
#include "sbptt/optim/step_checks.hpp"

namespace sbptt {

/// Hyper-parameters of `Adam`; the defaults are Keras's.
template <std::floating_point Scalar = double>
struct AdamOptions {
  Scalar learning_rate = Scalar(1e-3);  ///< lr > 0, finite
  Scalar beta1 = Scalar(0.9);           ///< decay of the first moment, in [0, 1)
  Scalar beta2 = Scalar(0.999);         ///< decay of the second moment, in [0, 1)
  Scalar epsilon = Scalar(1e-7);        ///< added to √v (not √v̂), finite and > 0
};


/// Adam on a flat parameter vector, Keras/TF form (see the file comment for the formula and
/// how it differs from PyTorch). State (m, v, t) is created on the first `step`.
template <std::floating_point S = double>
class Adam {
public:
  using Scalar = S;
  using Options = AdamOptions<Scalar>;

  Adam() : Adam(Options{}) {}

  /// Throws `InvalidArgument` naming the first option out of range.
  explicit Adam(const Options& options) : options_(options) {
    detail::require_learning_rate(options_.learning_rate, "Adam");
    detail::require_decay(options_.beta1, "Adam", "beta1");
    detail::require_decay(options_.beta2, "Adam", "beta2");
    detail::require(std::isfinite(options_.epsilon) && options_.epsilon > Scalar(0),
                    "Adam: epsilon = ", options_.epsilon,
                    "; expected a finite number > 0 (with 0, a component that is exactly 0 "
                    "from the start would divide 0 by 0)");
  }

  /// One update of `params` (size n) with `grad` (size n). Non-finite gradient entries are
  /// not rejected: they propagate as in the reference, and detecting them is the engine's job.
  void step(Vector<Scalar>& params, const Vector<Scalar>& grad) {
    detail::require_step_sizes(params, grad, m_.size(), iterations_ > 0, "Adam::step");
    if (iterations_ == 0) {
      m_.setZero(params.size());
      v_.setZero(params.size());
    }
    ++iterations_;
    // pow of the float step count, as Keras computes beta_1_power from the iteration count.
    const Scalar t = static_cast<Scalar>(iterations_);
    const Scalar beta1_power = std::pow(options_.beta1, t);
    const Scalar beta2_power = std::pow(options_.beta2, t);
    const Scalar alpha =
        options_.learning_rate * std::sqrt(Scalar(1) - beta2_power) / (Scalar(1) - beta1_power);
    m_.array() += (grad.array() - m_.array()) * (Scalar(1) - options_.beta1);
    v_.array() += (grad.array().square() - v_.array()) * (Scalar(1) - options_.beta2);
    params.array() -= (m_.array() * alpha) / (v_.array().sqrt() + options_.epsilon);
  }

  /// Number of steps taken since construction or `reset()` (t of the last step).
  [[nodiscard]] Index iterations() const { return iterations_; }

  /// Forgets m, v and t; the next step may use a vector of another size.
  void reset() {
    iterations_ = 0;
    m_.resize(0);
    v_.resize(0);
  }

  [[nodiscard]] const Options& options() const { return options_; }

  /// For schedules: changes lr from the next step on, keeping the moments.
  void set_learning_rate(Scalar learning_rate) {
    detail::require_learning_rate(learning_rate, "Adam::set_learning_rate");
    options_.learning_rate = learning_rate;
  }

  /// m (size n after the first step, empty before).
  [[nodiscard]] const Vector<Scalar>& first_moment() const { return m_; }
  /// v (size n after the first step, empty before).
  [[nodiscard]] const Vector<Scalar>& second_moment() const { return v_; }

  /// Restores a saved state (for checkpoints): m and v of equal size, v ≥ 0, t ≥ 0, and
  /// empty moments exactly when t = 0.
  void restore(Vector<Scalar> first_moment, Vector<Scalar> second_moment, Index iterations) {
    detail::require(first_moment.size() == second_moment.size(),
                    "Adam::restore: first moment size = ", first_moment.size(),
                    ", expected the second moment size ", second_moment.size());
    detail::require(iterations >= 0, "Adam::restore: iterations = ", iterations,
                    "; expected >= 0");
    detail::require((iterations == 0) == (first_moment.size() == 0),
                    "Adam::restore: iterations = ", iterations, " with moments of size ",
                    first_moment.size(), "; expected empty moments exactly when iterations = 0");
    detail::require((second_moment.array() >= Scalar(0)).all(),
                    "Adam::restore: second moment has an entry that is negative or NaN; "
                    "expected every entry >= 0");
    m_ = std::move(first_moment);
    v_ = std::move(second_moment);
    iterations_ = iterations;
  }

private:
  Options options_;
  Vector<Scalar> m_;
  Vector<Scalar> v_;
  Index iterations_ = 0;
};

}  // namespace sbptt
