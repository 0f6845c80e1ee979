#pragma once
/// \file The BPTT engine: one stored forward pass, then reverse sweeps in any flow mode.
///
/// Rollout of one sample (m steps):  c_n = N(x_n; θ),  x_{n+1} = P(x_n, c_n).
/// Loss: see objective.hpp; the batch loss is the mean over samples, so every loss seed
/// carries a factor 1/B. Reverse sweep (flow_mode.hpp), from λ_m = w·∂ℓ/∂x_m:
///
///     μ_n  = B_nᵀ λ_{n+1} + 2ρ/(m·k·B) · c_n
///     g   += (∂N/∂θ)_nᵀ μ_n
///     λ_n  = [n scored] w·∂ℓ/∂x_n / B + [physics] A_nᵀ λ_{n+1} + [network] K_nᵀ μ_n
///
/// With a truncation window K > 0 the two propagated terms are dropped at every step n that
/// is a positive multiple of K, so no gradient crosses those states.
#include <cmath>
#include <optional>

#include "sbptt/bptt/diagnostics.hpp"
#include "sbptt/bptt/flow_mode.hpp"
#include "sbptt/bptt/objective.hpp"
#include "sbptt/bptt/trajectory.hpp"
#include "sbptt/core/concepts.hpp"
#include "sbptt/core/error.hpp"

namespace sbptt {

/// Loss and both vectors the combined update needs, from one forward pass.
template <class Scalar>
struct GradientPair {
  Scalar loss = 0;
  Vector<Scalar> regular;   ///< g_R, the true gradient (Full)
  Vector<Scalar> modified;  ///< g_M, gradient stopped at the network input (PhysicsOnly)
  SweepDiagnostics regular_diagnostics;
  SweepDiagnostics modified_diagnostics;
  ComparisonDiagnostics comparison;
  std::optional<NonFinite> forward_non_finite;
};

/// Trains a `Controller` through a `Simulator`. Holds references: the simulator and the
/// controller must outlive the engine; the forward pass uses the controller's parameters at
/// the time of the call.
template <class Sim, class Ctrl, class Loss>
class Engine {
  static_assert(static_assert_simulator<Sim>());
  static_assert(static_assert_controller<Ctrl>());
  static_assert(StateLoss<Loss, typename Sim::State>,
                "sbptt::Engine: the loss needs `Scalar operator()(const State& x, State* grad) "
                "const` for the simulator's State");
  static_assert(std::is_same_v<typename Sim::Scalar, typename Ctrl::Scalar>,
                "sbptt::Engine: the simulator and the controller must use the same Scalar");

public:
  using Scalar = typename Sim::Scalar;
  using State = typename Sim::State;
  using Control = typename Sim::Control;

  /// \param steps the horizon m (> 0).
  Engine(const Sim& sim, const Ctrl& controller, Objective<Loss> objective, Index steps)
      : sim_(sim), controller_(controller), objective_(std::move(objective)), steps_(steps) {
    detail::require(steps > 0, "Engine: steps = ", steps, "; expected a horizon of at least 1");
    detail::require(controller.input_dim() == sim.state_dim(), "Engine: controller input_dim = ",
                    controller.input_dim(), "; expected the simulator's state_dim = ",
                    sim.state_dim());
    detail::require(controller.output_dim() == sim.control_dim(),
                    "Engine: controller output_dim = ", controller.output_dim(),
                    "; expected the simulator's control_dim = ", sim.control_dim());
    detail::require(std::isfinite(objective_.step_weight), "Engine: step_weight = ",
                    objective_.step_weight, "; expected a finite number");
    detail::require(std::isfinite(objective_.control_weight) && objective_.control_weight >= 0,
                    "Engine: control_weight = ", objective_.control_weight,
                    "; expected a finite number >= 0");
    x_.resize(sim.state_dim());
    x_next_.resize(sim.state_dim());
    seed_.resize(sim.state_dim());
    lambda_sample_.resize(sim.state_dim());
    lambda_x_.resize(sim.state_dim());
    u_.resize(sim.control_dim());
    lambda_u_.resize(sim.control_dim());
  }

  [[nodiscard]] Index steps() const { return steps_; }
  [[nodiscard]] const Objective<Loss>& objective() const { return objective_; }
  [[nodiscard]] const Trajectory<Scalar, typename Ctrl::Workspace>& trajectory() const {
    return trajectory_;
  }
  /// The first NaN/Inf of the last forward pass (state, control or loss), if any.
  [[nodiscard]] const std::optional<NonFinite>& forward_non_finite() const {
    return forward_non_finite_;
  }

  /// Rolls out the batch `initial_states` (state_dim × B), stores the trajectory and returns
  /// the batch-mean loss.
  Scalar forward(const Matrix<Scalar>& initial_states) {
    check_initial_states(initial_states, "forward");
    const Index batch = initial_states.cols();
    trajectory_.resize(steps_, sim_.state_dim(), sim_.control_dim(), batch);
    forward_non_finite_.reset();
    trajectory_.states[0] = initial_states;
    note_non_finite(Quantity::State, 0, trajectory_.states[0]);
    for (Index n = 0; n < steps_; ++n) {
      const auto i = static_cast<std::size_t>(n);
      controller_.forward(trajectory_.states[i], trajectory_.controls[i], trajectory_.workspaces[i]);
      note_non_finite(Quantity::Control, n, trajectory_.controls[i]);
      for (Index b = 0; b < batch; ++b) {
        x_ = trajectory_.states[i].col(b);
        u_ = trajectory_.controls[i].col(b);
        sim_.step(x_, u_, x_next_);
        trajectory_.states[i + 1].col(b) = x_next_;
      }
      note_non_finite(Quantity::State, n + 1, trajectory_.states[i + 1]);
    }
    return batch_loss();
  }

  /// Batch-mean loss of a rollout of `initial_states` (state_dim × B) without storing the
  /// trajectory: memory O(state_dim·B) whatever the horizon, for evaluating large sets.
  /// Leaves the stored trajectory untouched; a non-finite value is reported through
  /// `forward_non_finite()` like in `forward`.
  Scalar evaluate(const Matrix<Scalar>& initial_states) {
    check_initial_states(initial_states, "evaluate");
    const Index batch = initial_states.cols();
    forward_non_finite_.reset();
    eval_state_ = initial_states;
    eval_next_.resize(sim_.state_dim(), batch);
    const Scalar w = static_cast<Scalar>(objective_.step_weight);
    const Scalar control_scale = static_cast<Scalar>(
        objective_.control_weight / static_cast<double>(steps_ * sim_.control_dim()));
    eval_losses_.setZero(batch);
    for (Index n = 0; n < steps_; ++n) {
      controller_.forward(eval_state_, eval_control_, eval_workspace_);
      note_non_finite(Quantity::Control, n, eval_control_);
      for (Index b = 0; b < batch; ++b) {
        x_ = eval_state_.col(b);
        u_ = eval_control_.col(b);
        sim_.step(x_, u_, x_next_);
        eval_next_.col(b) = x_next_;
        if (objective_.control_weight > 0)
          eval_losses_(b) += control_scale * eval_control_.col(b).squaredNorm();
        if (objective_.timing == LossTiming::Continuous || n + 1 == steps_)
          eval_losses_(b) += w * objective_.state_loss(x_next_, static_cast<State*>(nullptr));
      }
      eval_state_.swap(eval_next_);
      note_non_finite(Quantity::State, n + 1, eval_state_);
    }
    return mean_of_samples(eval_losses_);
  }

  /// Reverse sweep over the stored trajectory. Sets `gradient` (num_params) to the vector of
  /// the chosen schedule and returns the sweep's diagnostics.
  /// \param truncation window K (0 = none): no gradient crosses x_n for n a positive
  ///        multiple of K.
  const SweepDiagnostics& reverse(const FlowSchedule& schedule, Vector<Scalar>& gradient,
                                  Index truncation = 0) {
    const Index batch = trajectory_.batch();
    detail::require(batch > 0 && trajectory_.steps() == steps_,
                    "Engine::reverse: no stored trajectory; call forward first");
    detail::require(truncation >= 0, "Engine::reverse: truncation = ", truncation,
                    "; expected 0 (none) or a window of at least 1 step");
    schedule.validate(steps_);
    const Index state_dim = sim_.state_dim();
    gradient.setZero(controller_.num_params());
    lambda_.setZero(state_dim, batch);
    mu_.resize(sim_.control_dim(), batch);
    propagated_.resize(state_dim, batch);
    sweep_.adjoint_norms.assign(static_cast<std::size_t>(steps_ + 1), 0.0);
    sweep_.first_non_finite.reset();

    add_loss_seed(steps_, lambda_);
    record_adjoint(steps_);
    const Scalar control_seed =
        static_cast<Scalar>(2.0 * objective_.control_weight /
                            static_cast<double>(steps_ * sim_.control_dim() * batch));
    for (Index n = steps_ - 1; n >= 0; --n) {
      const auto i = static_cast<std::size_t>(n);
      const FlowMode mode = schedule.at(n);
      const bool cut = truncation > 0 && n > 0 && n % truncation == 0;
      const bool physics = physics_flows(mode) && !cut;
      const bool network = network_flows(mode) && !cut;
      for (Index b = 0; b < batch; ++b) {
        x_ = trajectory_.states[i].col(b);
        u_ = trajectory_.controls[i].col(b);
        lambda_sample_ = lambda_.col(b);
        sim_.vjp(x_, u_, lambda_sample_, physics ? &lambda_x_ : nullptr, &lambda_u_);
        mu_.col(b) = lambda_u_;
        if (physics) propagated_.col(b) = lambda_x_;
      }
      if (objective_.control_weight > 0) mu_.noalias() += control_seed * trajectory_.controls[i];
      controller_.backward(trajectory_.workspaces[i], mu_, gradient,
                           network ? &input_adjoint_ : nullptr);
      if (physics) {
        lambda_.swap(propagated_);
        if (network) lambda_ += input_adjoint_;
      } else if (network) {
        lambda_ = input_adjoint_;
      } else {
        lambda_.setZero();
      }
      if (objective_.timing == LossTiming::Continuous && n > 0) add_loss_seed(n, lambda_);
      record_adjoint(n);
    }
    sweep_.grad_norm2 = static_cast<double>(gradient.squaredNorm());
    if (!sweep_.first_non_finite) {
      for (Index p = 0; p < gradient.size(); ++p) {
        if (!std::isfinite(gradient(p))) {
          sweep_.first_non_finite =
              NonFinite{Quantity::Gradient, -1, p, static_cast<double>(gradient(p))};
          break;
        }
      }
    }
    return sweep_;
  }

  /// One forward pass, then the Full (g_R) and PhysicsOnly (g_M) sweeps over it.
  GradientPair<Scalar> regular_and_modified(const Matrix<Scalar>& initial_states,
                                            Index truncation = 0) {
    GradientPair<Scalar> result;
    regular_and_modified(initial_states, result, truncation);
    return result;
  }

  /// As above, reusing the buffers of `result` (no allocation once sized).
  void regular_and_modified(const Matrix<Scalar>& initial_states, GradientPair<Scalar>& result,
                            Index truncation = 0) {
    result.loss = forward(initial_states);
    result.forward_non_finite = forward_non_finite_;
    result.regular_diagnostics = reverse(FlowMode::Full, result.regular, truncation);
    result.modified_diagnostics = reverse(FlowMode::PhysicsOnly, result.modified, truncation);
    result.comparison = compare(result.modified, result.regular);
  }

private:
  void check_initial_states(const Matrix<Scalar>& initial_states, const char* caller) const {
    detail::require(initial_states.rows() == sim_.state_dim(), "Engine::", caller, ": ",
                    initial_states.rows(), " rows in the initial states; expected state_dim = ",
                    sim_.state_dim());
    detail::require(initial_states.cols() > 0, "Engine::", caller,
                    ": an empty batch; expected at least one sample");
  }

  /// Batch-mean loss of the stored trajectory.
  Scalar batch_loss() {
    const Index batch = trajectory_.batch();
    const Scalar w = static_cast<Scalar>(objective_.step_weight);
    const Index first = objective_.timing == LossTiming::Final ? steps_ : 1;
    eval_losses_.setZero(batch);
    for (Index b = 0; b < batch; ++b) {
      for (Index n = first; n <= steps_; ++n) {
        x_ = trajectory_.states[static_cast<std::size_t>(n)].col(b);
        eval_losses_(b) += w * objective_.state_loss(x_, static_cast<State*>(nullptr));
      }
      if (objective_.control_weight > 0) {
        Scalar squares = 0;
        for (const auto& c : trajectory_.controls) squares += c.col(b).squaredNorm();
        eval_losses_(b) += static_cast<Scalar>(objective_.control_weight /
                                               static_cast<double>(steps_ * sim_.control_dim())) *
                           squares;
      }
    }
    return mean_of_samples(eval_losses_);
  }

  /// Mean of per-sample losses, summed in sample order (thread-count independent); notes the
  /// first non-finite sample loss.
  Scalar mean_of_samples(const Vector<Scalar>& losses) {
    Scalar total = 0;
    for (Index b = 0; b < losses.size(); ++b) {
      if (!forward_non_finite_ && !std::isfinite(losses(b)))
        forward_non_finite_ = NonFinite{Quantity::Loss, steps_, b, static_cast<double>(losses(b))};
      total += losses(b);
    }
    return total / static_cast<Scalar>(losses.size());
  }

  /// lambda.col(b) += w/B · ∂ℓ/∂x_n for every sample b.
  void add_loss_seed(Index n, Matrix<Scalar>& lambda) {
    const Index batch = trajectory_.batch();
    const Scalar scale =
        static_cast<Scalar>(objective_.step_weight / static_cast<double>(batch));
    for (Index b = 0; b < batch; ++b) {
      x_ = trajectory_.states[static_cast<std::size_t>(n)].col(b);
      objective_.state_loss(x_, &seed_);
      lambda.col(b) += scale * seed_;
    }
  }

  void record_adjoint(Index n) {
    sweep_.adjoint_norms[static_cast<std::size_t>(n)] = static_cast<double>(lambda_.norm());
    if (!sweep_.first_non_finite) note_first(Quantity::Adjoint, n, lambda_, sweep_.first_non_finite);
  }

  void note_non_finite(Quantity quantity, Index n, const Matrix<Scalar>& values) {
    if (!forward_non_finite_) note_first(quantity, n, values, forward_non_finite_);
  }

  static void note_first(Quantity quantity, Index n, const Matrix<Scalar>& values,
                         std::optional<NonFinite>& slot) {
    if (values.allFinite()) return;
    for (Index b = 0; b < values.cols(); ++b) {
      for (Index r = 0; r < values.rows(); ++r) {
        if (!std::isfinite(values(r, b))) {
          slot = NonFinite{quantity, n, b, static_cast<double>(values(r, b))};
          return;
        }
      }
    }
  }

  const Sim& sim_;
  const Ctrl& controller_;
  Objective<Loss> objective_;
  Index steps_;

  Trajectory<Scalar, typename Ctrl::Workspace> trajectory_;
  std::optional<NonFinite> forward_non_finite_;
  SweepDiagnostics sweep_;
  Matrix<Scalar> lambda_, propagated_, mu_, input_adjoint_;
  Matrix<Scalar> eval_state_, eval_next_, eval_control_;
  typename Ctrl::Workspace eval_workspace_;
  Vector<Scalar> eval_losses_;
  State x_, x_next_, seed_, lambda_sample_, lambda_x_;
  Control u_, lambda_u_;
};

}  // namespace sbptt
