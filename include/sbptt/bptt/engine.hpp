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
///
/// Cost and memory: the controller runs once per step on the whole batch (one product per
/// layer, never per sample); a `PackingController` packs its parameters once per rollout
/// (`forward`, `evaluate`), and the reverse sweeps use the packing of the last of those. The
/// simulator, the loss and their VJPs run per sample. After the first call at a batch shape,
/// `forward`, `reverse` and `regular_and_modified` allocate nothing (every buffer is kept and
/// resized only when the shape changes).
///
/// Threads (`set_threads`): the per-sample work of a step (simulator step and VJP, loss seeds)
/// is split over the samples; `regular_and_modified` runs its two sweeps at once; `evaluate`
/// rolls out fixed chunks of `kEvaluateChunk` samples independently. A lone sweep (`reverse`)
/// whose per-sample loops are too cheap to split hands the parameter products of a
/// `SplitBackwardController` to a second thread instead, step by step, and adds them in step
/// order (engine_buffers.hpp, `ParamHandoff`). Every sample is computed
/// by the same operations whatever the thread count, and every batch sum is taken in a fixed
/// order, so all results are bitwise identical for any number of threads. With more than one
/// thread the controller's `backward` must be safe to call concurrently on one workspace, a
/// `SplitBackwardController`'s `add_param_gradient` concurrently with `backward_inputs` of
/// another step (`Network`'s are), and the loss functor must be thread-safe (a `const` pure
/// function).
#include <cmath>
#include <memory>
#include <optional>
#include <vector>

#include "sbptt/bptt/diagnostics.hpp"
#include "sbptt/bptt/flow_mode.hpp"
#include "sbptt/bptt/objective.hpp"
#include "sbptt/bptt/trajectory.hpp"
#include "sbptt/core/concepts.hpp"
#include "sbptt/core/error.hpp"
#include "sbptt/bptt/engine_buffers.hpp"
#include "sbptt/bptt/packed_controller.hpp"
#include "sbptt/core/parallel.hpp"

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

  /// Samples per independently rolled-out chunk of `evaluate` (a constant, so that the result
  /// does not depend on the number of threads).
  static constexpr Index kEvaluateChunk = 32;

  /// \param steps the horizon m (> 0).
  Engine(const Sim& sim, const Ctrl& controller, Objective<Loss> objective, Index steps)
      : sim_(sim), controller_(controller), objective_(std::move(objective)), steps_(steps) {
    detail::require(steps > 0, "Engine: steps = ", steps, "; expected a horizon of at least 1");
    detail::require(State::SizeAtCompileTime == Eigen::Dynamic ||
                        State::SizeAtCompileTime == sim.state_dim(),
                    "Engine: the simulator's State holds ", State::SizeAtCompileTime,
                    " numbers but its state_dim() = ", sim.state_dim(),
                    "; expected them to agree");
    detail::require(Control::SizeAtCompileTime == Eigen::Dynamic ||
                        Control::SizeAtCompileTime == sim.control_dim(),
                    "Engine: the simulator's Control holds ", Control::SizeAtCompileTime,
                    " numbers but its control_dim() = ", sim.control_dim(),
                    "; expected them to agree");
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
    set_threads(1);
  }

  /// The engine keeps references to the simulator and the controller: a temporary would be
  /// destroyed at the end of the statement, so binding one is refused at compile time.
  Engine(const Sim&& temporary_simulator, const Ctrl& controller, Objective<Loss> objective,
         Index steps) = delete;
  Engine(const Sim& sim, const Ctrl&& temporary_controller, Objective<Loss> objective,
         Index steps) = delete;
  Engine(const Sim&& temporary_simulator, const Ctrl&& temporary_controller,
         Objective<Loss> objective, Index steps) = delete;

  [[nodiscard]] Index steps() const { return steps_; }
  [[nodiscard]] const Objective<Loss>& objective() const { return objective_; }
  [[nodiscard]] const Trajectory<Scalar, typename Ctrl::Workspace>& trajectory() const {
    return trajectory_;
  }
  /// The first NaN/Inf of the last forward pass (state, control or loss), if any.
  [[nodiscard]] const std::optional<NonFinite>& forward_non_finite() const {
    return forward_non_finite_;
  }

  /// Threads for the per-sample work (≥ 1; 1 = none started). Results do not depend on it
  /// (see the file comment). Starts or stops the engine's worker threads.
  /// \param split_above_ns a per-sample loop of a step (simulator steps, VJPs, losses) is
  ///        split over the threads only when it takes at least this long on one thread
  ///        (timed on its first calls): a fork costs about a microsecond, more than a cheap
  ///        simulator's whole batch. 0 splits every loop.
  void set_threads(Index threads, double split_above_ns = 4000) {
    detail::require(threads >= 1, "Engine::set_threads: threads = ", threads,
                    "; expected at least 1");
    detail::require(split_above_ns >= 0, "Engine::set_threads: split_above_ns = ",
                    split_above_ns, "; expected a number of nanoseconds >= 0");
    pool_ = threads > 1 ? std::make_unique<detail::ThreadPool>(threads) : nullptr;
    if constexpr (SplitBackwardController<Ctrl>)
      handoff_ = pool_ ? std::make_unique<Handoff>() : nullptr;
    if constexpr (SeedScalingController<Ctrl>)
      shared_handoff_ = pool_ ? std::make_unique<SharedHandoff>() : nullptr;
    threads_ = threads;
    for (auto& decision : fork_) decision = detail::ForkDecision(split_above_ns);
    const auto slots = static_cast<std::size_t>(threads);
    for (auto* scratch : {&forward_scratch_, &sweeps_[0].scratch, &sweeps_[1].scratch})
      scratch->assign(slots, make_scratch());
  }
  [[nodiscard]] Index threads() const { return threads_; }

  /// Rolls out the batch `initial_states` (state_dim × B), stores the trajectory and returns
  /// the batch-mean loss.
  Scalar forward(const Matrix<Scalar>& initial_states) {
    check_initial_states(initial_states, "forward");
    const Index batch = initial_states.cols();
    trajectory_.resize(steps_, sim_.state_dim(), sim_.control_dim(), batch);
    forward_non_finite_.reset();
    trajectory_.states[0] = initial_states;
    note_non_finite(Quantity::State, 0, trajectory_.states[0]);
    packed_controller_.pack();
    for (Index n = 0; n < steps_; ++n) {
      const auto i = static_cast<std::size_t>(n);
      packed_controller_.forward(trajectory_.states[i], trajectory_.controls[i],
                                 trajectory_.workspaces[i]);
      note_non_finite(Quantity::Control, n, trajectory_.controls[i]);
      fork_[0].for_samples(pool_.get(), batch, forward_scratch_, true, [&](Index b, Scratch& t) {
        t.x = trajectory_.states[i].col(b);
        t.u = trajectory_.controls[i].col(b);
        sim_.step(t.x, t.u, t.x_next);
        trajectory_.states[i + 1].col(b) = t.x_next;
      });
      note_non_finite(Quantity::State, n + 1, trajectory_.states[i + 1]);
    }
    return batch_loss();
  }

  /// Batch-mean loss of a rollout of `initial_states` (state_dim × B) without storing the
  /// trajectory: memory O(B·(state_dim + network widths)) whatever the horizon, for large sets.
  /// Leaves the stored trajectory untouched; a non-finite value is reported through
  /// `forward_non_finite()` like in `forward`. Chunks of `kEvaluateChunk` samples are rolled
  /// out independently (in parallel with threads).
  Scalar evaluate(const Matrix<Scalar>& initial_states) {
    check_initial_states(initial_states, "evaluate");
    const Index batch = initial_states.cols();
    const Index chunks = (batch + kEvaluateChunk - 1) / kEvaluateChunk;
    if (static_cast<Index>(chunks_.size()) < chunks)
      chunks_.resize(static_cast<std::size_t>(chunks));
    eval_losses_.resize(batch);
    packed_controller_.pack();
    auto task = [&](Index k, Index) {
      const Index first = k * kEvaluateChunk;
      const Index size = std::min(kEvaluateChunk, batch - first);
      chunks_[static_cast<std::size_t>(k)].roll_out(sim_, packed_controller_, objective_, steps_,
                                                    initial_states.middleCols(first, size), first,
                                                    eval_losses_.segment(first, size));
    };
    if (pool_) {
      pool_->run(chunks, task);
    } else {
      for (Index k = 0; k < chunks; ++k) task(k, 0);
    }
    // The first non-finite value in rollout order: by step, control before state, then sample.
    forward_non_finite_.reset();
    Index best = -1;
    for (Index k = 0; k < chunks; ++k) {
      const EvalChunk& chunk = chunks_[static_cast<std::size_t>(k)];
      if (chunk.non_finite && (best < 0 || chunk.order < best)) {
        best = chunk.order;
        forward_non_finite_ = chunk.non_finite;
      }
    }
    return detail::mean_of_samples(eval_losses_, steps_, forward_non_finite_);
  }

  /// Reverse sweep over the stored trajectory. Sets `gradient` (num_params) to the vector of
  /// the chosen schedule and returns the sweep's diagnostics.
  /// \param truncation window K (0 = none): no gradient crosses x_n for n a positive
  ///        multiple of K.
  const SweepDiagnostics& reverse(const FlowSchedule& schedule, Vector<Scalar>& gradient,
                                  Index truncation = 0) {
    check_sweep(schedule, truncation);
    if constexpr (SplitBackwardController<Ctrl>) {
      // Only once the simulator's loops have been found too cheap to split: the second
      // thread then has nothing better to do than the parameter products.
      if (handoff_ && !fork_[1].probing() && !fork_[1].fork()) {
        Handoff& h = *handoff_;
        auto add = [&](std::size_t slot) { add_params(h, slot, gradient); };
        h.run(*pool_, steps_, add,
              [&] { sweep(sweeps_[0], schedule, gradient, truncation, false, &h); });
        return sweeps_[0].diagnostics;
      }
    }
    sweep(sweeps_[0], schedule, gradient, truncation, true);
    return sweeps_[0].diagnostics;
  }

  /// One forward pass, then the Full (g_R) and PhysicsOnly (g_M) sweeps over it.
  GradientPair<Scalar> regular_and_modified(const Matrix<Scalar>& initial_states,
                                            Index truncation = 0) {
    GradientPair<Scalar> result;
    regular_and_modified(initial_states, result, truncation);
    return result;
  }

  /// As above, reusing the buffers of `result` (no allocation once sized). With one control
  /// and a `SeedScalingController` both sweeps share one backward pass of the controller
  /// (`shared_seed_sweeps`); otherwise, with threads, the two sweeps run at the same time,
  /// each exactly as it would alone.
  void regular_and_modified(const Matrix<Scalar>& initial_states, GradientPair<Scalar>& result,
                            Index truncation = 0) {
    result.loss = forward(initial_states);
    result.forward_non_finite = forward_non_finite_;
    check_sweep(FlowMode::Full, truncation);
    if constexpr (SeedScalingController<Ctrl>) {
      if (sim_.control_dim() == 1) {
        shared_seed_sweeps(result, truncation);
        finish_pair(result);
        return;
      }
    }
    auto task = [&](Index item, Index) {
      if (item == 0) {
        sweep(sweeps_[0], FlowMode::Full, result.regular, truncation, !pool_);
      } else {
        sweep(sweeps_[1], FlowMode::PhysicsOnly, result.modified, truncation, !pool_);
      }
    };
    if (pool_) {
      pool_->run(2, task);
    } else {
      task(0, 0);
      task(1, 0);
    }
    finish_pair(result);
  }

private:
  using Scratch = detail::SampleScratch<State, Control>;
  using Sweep = detail::SweepBuffers<Scalar, Scratch>;
  using EvalChunk = detail::EvaluationChunk<Scalar, typename Ctrl::Workspace, Scratch>;

  using Handoff = typename detail::ParamHandoffOf<Ctrl>::Type;
  using SharedHandoff = typename detail::SharedSeedHandoffOf<Ctrl>::Type;
  using SharedStep = typename detail::SharedSeedHandoffOf<Ctrl>::Step;

  /// Adds the parameter products recorded in `slot` of the hand-off to `gradient`.
  void add_params(Handoff& h, std::size_t slot, Vector<Scalar>& gradient) const {
    if constexpr (SplitBackwardController<Ctrl>) {
      const auto step = static_cast<std::size_t>(h.steps[slot]);
      controller_.add_param_gradient(trajectory_.workspaces[step], h.ring[slot], gradient);
    }
  }

  [[nodiscard]] Scratch make_scratch() const {
    return Scratch(sim_.state_dim(), sim_.control_dim());
  }

  void check_initial_states(const Matrix<Scalar>& initial_states, const char* caller) const {
    detail::require(initial_states.rows() == sim_.state_dim(), "Engine::", caller, ": ",
                    initial_states.rows(), " rows in the initial states; expected state_dim = ",
                    sim_.state_dim());
    detail::require(initial_states.cols() > 0, "Engine::", caller,
                    ": an empty batch; expected at least one sample");
  }

  void check_sweep(const FlowSchedule& schedule, Index truncation) const {
    detail::require(trajectory_.batch() > 0 && trajectory_.steps() == steps_,
                    "Engine::reverse: no stored trajectory; call forward first");
    detail::require(truncation >= 0, "Engine::reverse: truncation = ", truncation,
                    "; expected 0 (none) or a window of at least 1 step");
    schedule.validate(steps_);
  }

  /// The reverse sweep of the file comment into `s` and `gradient`. The loss seed of x_{n+1}
  /// is added in the same per-sample pass as the VJPs of step n.
  /// With `handoff` the parameter products go through it (`reverse`), else they are done here.
  void sweep(Sweep& s, const FlowSchedule& schedule, Vector<Scalar>& gradient, Index truncation,
             bool parallel, Handoff* handoff = nullptr) {
    begin_sweep(s, gradient, handoff != nullptr);
    auto add = [&](std::size_t slot) { add_params(*handoff, slot, gradient); };
    for (Index n = steps_ - 1; n >= 0; --n) {
      const auto i = static_cast<std::size_t>(n);
      const FlowMode mode = schedule.at(n);
      const bool cut = truncation > 0 && n > 0 && n % truncation == 0;
      const bool physics = physics_flows(mode) && !cut;
      const bool network = network_flows(mode) && !cut;
      adjoint_products(s, n, physics, parallel);
      Matrix<Scalar>* input_adjoint = network ? &s.input_adjoint : nullptr;
      if constexpr (SplitBackwardController<Ctrl>) {
        if (handoff != nullptr) {
          const Index k = steps_ - 1 - n;  // recordings so far
          const std::size_t slot = handoff->slot_for(k, add);
          packed_controller_.backward_inputs(trajectory_.workspaces[i], s.mu, input_adjoint,
                                 handoff->ring[slot]);
          handoff->steps[slot] = n;
          handoff->recorded.store(k + 1, std::memory_order_release);
        }
      }
      if (handoff == nullptr)
        packed_controller_.backward(trajectory_.workspaces[i], s.mu, gradient, input_adjoint);
      if (physics) {
        s.lambda.swap(s.propagated);
        if (network) s.lambda += s.input_adjoint;
      } else if (network) {
        s.lambda = s.input_adjoint;
      } else {
        s.lambda.setZero();
      }
    }
    if constexpr (SplitBackwardController<Ctrl>) {
      if (handoff != nullptr) handoff->wait_added(steps_, add);
    }
    end_sweep(s, gradient);
  }

  /// Both sweeps of `regular_and_modified` with one backward pass of the controller per step.
  /// With a single control, μ_n of each sweep is a row (1 × B) and the controller's backward is
  /// linear in each sample's seed, so the layer adjoints of the seed 1 serve both: each sweep
  /// scales them by its own μ_n for its parameter products, and the Full sweep its input
  /// adjoint K_nᵀ1 for λ_n. That saves the PhysicsOnly sweep's layer VJPs. With threads, the
  /// parameter products run on a second thread, in step order as on one thread
  /// (`ParamHandoff`), so the results do not depend on the thread count.
  void shared_seed_sweeps(GradientPair<Scalar>& result, Index truncation)
    requires SeedScalingController<Ctrl>
  {
    if (!pool_) {
      shared_seed_sweep(result, truncation, nullptr);
      return;
    }
    SharedHandoff& h = *shared_handoff_;
    auto add = [&](std::size_t slot) {
      add_shared_step(h.ring[slot], h.steps[slot], result);
    };
    h.run(*pool_, steps_, add, [&] { shared_seed_sweep(result, truncation, &h); });
  }

  void shared_seed_sweep(GradientPair<Scalar>& result, Index truncation, SharedHandoff* handoff)
    requires SeedScalingController<Ctrl>
  {
    const Index batch = trajectory_.batch();
    Sweep& full = sweeps_[0];
    Sweep& physics = sweeps_[1];
    begin_sweep(full, result.regular, handoff != nullptr);
    begin_sweep(physics, result.modified, handoff != nullptr);
    unit_seed_.setOnes(1, batch);
    auto add = [&](std::size_t slot) {
      add_shared_step(handoff->ring[slot], handoff->steps[slot], result);
    };
    for (Index n = steps_ - 1; n >= 0; --n) {
      const auto i = static_cast<std::size_t>(n);
      const bool cut = truncation > 0 && n > 0 && n % truncation == 0;
      adjoint_products(full, n, !cut, handoff == nullptr);
      adjoint_products(physics, n, !cut, handoff == nullptr);
      const Index k = steps_ - 1 - n;  // steps recorded so far
      const std::size_t slot = handoff != nullptr ? handoff->slot_for(k, add) : 0;
      SharedStep& step = handoff != nullptr ? handoff->ring[slot] : shared_step_;
      step.full_mu = full.mu;
      step.physics_mu = physics.mu;
      packed_controller_.backward_inputs(trajectory_.workspaces[i], unit_seed_,
                                         cut ? nullptr : &full.input_adjoint, step.adjoints);
      if (handoff != nullptr) {
        handoff->steps[slot] = n;
        handoff->recorded.store(k + 1, std::memory_order_release);
      } else {
        add_shared_step(step, n, result);
      }
      if (cut) {
        full.lambda.setZero();
        physics.lambda.setZero();
      } else {
        full.lambda.swap(full.propagated);
        full.lambda.array() += full.input_adjoint.array().rowwise() * full.mu.row(0).array();
        physics.lambda.swap(physics.propagated);
      }
    }
    if (handoff != nullptr) handoff->wait_added(steps_, add);
    end_sweep(full, result.regular);
    end_sweep(physics, result.modified);
  }

  /// Adds both sweeps' parameter products of the step `n` recorded in `step`.
  void add_shared_step(const SharedStep& step, Index n, GradientPair<Scalar>& result) const
    requires SeedScalingController<Ctrl>
  {
    const auto& workspace = trajectory_.workspaces[static_cast<std::size_t>(n)];
    controller_.add_param_gradient(workspace, step.adjoints, step.full_mu, result.regular);
    controller_.add_param_gradient(workspace, step.adjoints, step.physics_mu, result.modified);
  }

  /// The per-sample half of step n of sweep `s`: λ_{n+1} += its loss seed, μ_n = B_nᵀλ_{n+1}
  /// (plus the control seed) and, when `physics`, A_nᵀλ_{n+1} into `s.propagated`.
  void adjoint_products(Sweep& s, Index n, bool physics, bool parallel) {
    const auto i = static_cast<std::size_t>(n);
    const Scalar seed_scale = loss_seed_scale();
    const bool scored = objective_.timing == LossTiming::Continuous || n + 1 == steps_;
    fork_[1].for_samples(pool_.get(), trajectory_.batch(), s.scratch, parallel,
                         [&](Index b, Scratch& t) {
      if (scored) {  // λ_{n+1} += w/B · ∂ℓ/∂x_{n+1}
        t.x = trajectory_.states[i + 1].col(b);
        objective_.state_loss(t.x, &t.seed);
        s.lambda.col(b) += seed_scale * t.seed;
      }
      t.x = trajectory_.states[i].col(b);
      t.u = trajectory_.controls[i].col(b);
      t.lambda_sample = s.lambda.col(b);
      sim_.vjp(t.x, t.u, t.lambda_sample, physics ? &t.lambda_x : nullptr, &t.lambda_u);
      s.mu.col(b) = t.lambda_u;
      if (physics) s.propagated.col(b) = t.lambda_x;
    });
    record_adjoint(s, n + 1);
    if (objective_.control_weight > 0)
      s.mu.noalias() += control_seed_scale() * trajectory_.controls[i];
  }

  void begin_sweep(Sweep& s, Vector<Scalar>& gradient, bool overlapped) {
    const Index batch = trajectory_.batch();
    gradient.setZero(controller_.num_params());
    s.lambda.setZero(sim_.state_dim(), batch);
    s.mu.resize(sim_.control_dim(), batch);
    s.propagated.resize(sim_.state_dim(), batch);
    s.diagnostics.adjoint_norms.assign(static_cast<std::size_t>(steps_ + 1), 0.0);
    s.diagnostics.first_non_finite.reset();
    s.diagnostics.params_overlapped = overlapped;
  }

  void end_sweep(Sweep& s, const Vector<Scalar>& gradient) {
    record_adjoint(s, 0);
    s.diagnostics.grad_norm2 = static_cast<double>(gradient.squaredNorm());
    if (!s.diagnostics.first_non_finite)
      s.diagnostics.first_non_finite = detail::first_non_finite_component(gradient);
  }

  void finish_pair(GradientPair<Scalar>& result) const {
    result.regular_diagnostics = sweeps_[0].diagnostics;
    result.modified_diagnostics = sweeps_[1].diagnostics;
    result.comparison = compare(result.modified, result.regular);
  }

  /// w/B, the factor of every loss seed; and 2ρ/(m·k·B), that of the control term of μ_n.
  [[nodiscard]] Scalar loss_seed_scale() const {
    return static_cast<Scalar>(objective_.step_weight /
                               static_cast<double>(trajectory_.batch()));
  }
  [[nodiscard]] Scalar control_seed_scale() const {
    return static_cast<Scalar>(2.0 * objective_.control_weight /
                               static_cast<double>(steps_ * sim_.control_dim() *
                                                   trajectory_.batch()));
  }

  /// Batch-mean loss of the stored trajectory.
  Scalar batch_loss() {
    const Index batch = trajectory_.batch();
    const Scalar w = static_cast<Scalar>(objective_.step_weight);
    const Index first = objective_.timing == LossTiming::Final ? steps_ : 1;
    eval_losses_.setZero(batch);
    fork_[2].for_samples(pool_.get(), batch, forward_scratch_, true, [&](Index b, Scratch& t) {
      for (Index n = first; n <= steps_; ++n) {
        t.x = trajectory_.states[static_cast<std::size_t>(n)].col(b);
        eval_losses_(b) += w * objective_.state_loss(t.x, static_cast<State*>(nullptr));
      }
      if (objective_.control_weight > 0) {
        Scalar squares = 0;
        for (const auto& c : trajectory_.controls) squares += c.col(b).squaredNorm();
        eval_losses_(b) += static_cast<Scalar>(objective_.control_weight /
                                               static_cast<double>(steps_ * sim_.control_dim())) *
                           squares;
      }
    });
    return detail::mean_of_samples(eval_losses_, steps_, forward_non_finite_);
  }

  void record_adjoint(Sweep& s, Index n) {
    s.diagnostics.adjoint_norms[static_cast<std::size_t>(n)] =
        static_cast<double>(s.lambda.norm());
    if (!s.diagnostics.first_non_finite)
      detail::note_first_non_finite(Quantity::Adjoint, n, s.lambda,
                                    s.diagnostics.first_non_finite);
  }

  void note_non_finite(Quantity quantity, Index n, const Matrix<Scalar>& values) {
    if (!forward_non_finite_)
      detail::note_first_non_finite(quantity, n, values, forward_non_finite_);
  }

  const Sim& sim_;
  const Ctrl& controller_;
  Objective<Loss> objective_;
  Index steps_;
  Index threads_ = 1;
  std::unique_ptr<Handoff> handoff_;  ///< with a pool and a SplitBackwardController
  std::unique_ptr<SharedHandoff> shared_handoff_;  ///< with a pool and a SeedScalingController
  SharedStep shared_step_;  ///< the one step of `shared_seed_sweep` on one thread
  Matrix<Scalar> unit_seed_;  ///< 1 × B ones
  detail::PackedController<Ctrl> packed_controller_{controller_};

  Trajectory<Scalar, typename Ctrl::Workspace> trajectory_;
  std::optional<NonFinite> forward_non_finite_;
  std::vector<Scratch> forward_scratch_;
  detail::ForkDecision fork_[3];  ///< per-sample loops: simulator step, VJPs, batch loss
  Sweep sweeps_[2];
  std::vector<EvalChunk> chunks_;
  Vector<Scalar> eval_losses_;
  // Last, so that it is destroyed first: its workers stop before the buffers they work on go.
  std::unique_ptr<detail::ThreadPool> pool_;
};

}  // namespace sbptt
