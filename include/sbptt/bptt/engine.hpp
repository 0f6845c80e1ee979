#pragma once
/// \file The BPTT engine: one stored forward pass, then reverse sweeps in any flow mode.
///
/// Rollout of one sample (m steps):  c_n = N(x_n; θ),  x_{n+1} = P(x_n, c_n).
/// Loss: see objective.hpp; the batch loss is the mean over samples, so every loss seed
/// carries a factor 1/B. Reverse sweep (flow_mode.hpp; its loops: reverse_sweeps.hpp), from
/// λ_m = w·∂ℓ/∂x_m:
///
///     μ_n  = B_nᵀ λ_{n+1} + 2ρ/(m·k·B) · c_n
///     g   += (∂N/∂θ)_nᵀ μ_n
///     λ_n  = [n scored] w·∂ℓ/∂x_n / B + [physics] A_nᵀ λ_{n+1} + [network] K_nᵀ μ_n
///
/// With a truncation window K > 0 the two propagated terms are dropped at every step n that
/// is a positive multiple of K, so no gradient crosses those states.
///
/// Cost and memory: the controller runs once per step on the whole batch (one product per
/// layer, never per sample; on several threads, once per step on each thread's part of it); a
/// `PackingController` packs its parameters once per rollout
/// (`forward`, `evaluate`), and the reverse sweeps use the packing of the last of those. The
/// simulator, the loss and their VJPs run per sample, except that a `BatchSimulator` steps and
/// differentiates the whole batch (or a thread's part of it) in one call (batch_physics.hpp).
/// After the first call at a batch shape, `forward`, `reverse` and `regular_and_modified`
/// allocate nothing (every buffer is kept and resized only when the shape changes).
///
/// Threads (`set_threads`): with a `ColumnSplitController`, `forward` cuts the batch into one
/// range of columns per thread and rolls each out from x_0 to x_m on its own thread; else the
/// per-sample work of a step (simulator step and VJP, loss seeds;
/// only the seeds for a `BatchSimulator`) is split over the samples; `evaluate` rolls out
/// fixed chunks of `kEvaluateChunk` samples independently. A lone sweep (`reverse`) whose
/// per-sample loops are too cheap to split hands the parameter products of a
/// `SplitBackwardController` to a second thread instead, step by step, and adds them in step
/// order (param_handoff.hpp, `ParamHandoff`). The pair of `regular_and_modified` splits its
/// steps between two threads when its sweeps share one backward pass (one control:
/// shared_seed_sweeps.hpp, step_split.hpp), else its two sweeps run at once. A batch whose
/// sweep meets the other thread at every step (the lone sweep's split loops or hand-off, the
/// split pair) runs on the calling thread alone instead, its forward pass included, while
/// that is faster (timed now and then: `SweepThreading`, sweep_threading.hpp). Every
/// sample is computed by the same operations whatever the thread count, and every batch sum is
/// taken in a fixed order, so all results are bitwise identical for any number of threads, and
/// whichever way a sweep ran. With more than one thread the controller's `backward` must be
/// safe to call concurrently on one workspace,
/// its `add_param_gradient` (both) concurrently with `backward_inputs` of another step,
/// `backward_inputs` concurrently with itself into different records, and the scaled
/// `add_param_gradient` concurrently with itself on different steps, with different `scaled`
/// buffers and gradients (`Network`'s are all of
/// these), and the loss functor must be thread-safe (a `const` pure function).
#include <algorithm>
#include <cmath>
#include <initializer_list>
#include <memory>
#include <optional>
#include <vector>

#include "sbptt/bptt/batch_physics.hpp"
#include "sbptt/bptt/batch_threading.hpp"
#include "sbptt/bptt/chunked_evaluation.hpp"
#include "sbptt/bptt/diagnostics.hpp"
#include "sbptt/bptt/flow_mode.hpp"
#include "sbptt/bptt/objective.hpp"
#include "sbptt/bptt/trajectory.hpp"
#include "sbptt/core/concepts.hpp"
#include "sbptt/core/error.hpp"
#include "sbptt/bptt/engine_buffers.hpp"
#include "sbptt/bptt/fork_decision.hpp"
#include "sbptt/bptt/forward_in_parts.hpp"
#include "sbptt/bptt/packed_controller.hpp"
#include "sbptt/bptt/param_handoff.hpp"
#include "sbptt/bptt/reverse_sweeps.hpp"
#include "sbptt/bptt/shared_seed_sweeps.hpp"
#include "sbptt/bptt/sweep_threading.hpp"
#include "sbptt/core/parallel.hpp"

namespace sbptt {

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
  static constexpr Index kEvaluateChunk = detail::evaluation_chunk_samples;

  /// `set_threads`' default `split_above_ns`.
  static constexpr double kDefaultSplitAboveNs = detail::ForkDecision::default_threshold_ns;

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
    if constexpr (requires(const Loss& loss) { loss.check_state_dim(Index{}); })
      objective_.state_loss.check_state_dim(sim.state_dim());
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

  [[nodiscard]] const Sim& simulator() const { return sim_; }
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
  /// \param split_above_ns a per-sample loop of a step (simulator steps, VJPs, losses; only the
  ///        losses for a `BatchSimulator`) is
  ///        split over the threads only when it takes at least this long on one thread
  ///        (timed on its first calls): a fork costs about a microsecond, more than a cheap
  ///        simulator's whole batch. 0 splits every loop. The forward pass of a
  ///        `ColumnSplitController` is done in parts, with one fork per rollout, unless its
  ///        batch runs on one thread (`sweep_threading`).
  /// \param sweep_threading whether a batch whose sweep meets the other thread at every step
  ///        uses the threads (`SweepThreading`: by default timed against one thread now and
  ///        then).
  void set_threads(Index threads, double split_above_ns = kDefaultSplitAboveNs,
                   SweepThreading sweep_threading = SweepThreading::Timed) {
    detail::require(threads >= 1, "Engine::set_threads: threads = ", threads,
                    "; expected at least 1");
    detail::require(split_above_ns >= 0, "Engine::set_threads: split_above_ns = ",
                    split_above_ns, "; expected a number of nanoseconds >= 0");
    pool_ = threads > 1 ? std::make_unique<detail::ThreadPool>(threads) : nullptr;
    if constexpr (SplitBackwardController<Ctrl>)
      handoff_ = pool_ ? std::make_unique<Handoff>() : nullptr;
    if constexpr (SeedScalingController<Ctrl>) shared_seed_.set_threaded(pool_ != nullptr);
    threads_ = threads;
    for (auto& decision : fork_) decision = detail::ForkDecision(split_above_ns);
    batch_threading_ = detail::BatchThreading(sweep_threading);
    const auto slots = static_cast<std::size_t>(threads);
    for (auto* scratch : {&forward_scratch_, &sweeps_[0].scratch, &sweeps_[1].scratch})
      scratch->assign(slots, Scratch(sim_.state_dim(), sim_.control_dim()));
    forward_in_parts_.resize(slots);
  }
  [[nodiscard]] Index threads() const { return threads_; }
  /// How the batches that `SweepThreading` applies to ran since `set_threads`: those of lone
  /// sweeps and of shared-seed pairs together.
  [[nodiscard]] SweepTally sweep_tally() const { return batch_threading_.tally(); }

  /// Rolls out the batch `initial_states` (state_dim × B), stores the trajectory and returns
  /// the batch-mean loss. With threads, the rollout and the next `reverse` go one way
  /// (`SweepThreading`). A rollout that throws (the simulator's or the controller's exception
  /// passes through) leaves no trajectory to sweep: `reverse` then refuses, as before any
  /// forward pass, and `trajectory()` holds the broken rollout's first steps, not a rollout.
  Scalar forward(const Matrix<Scalar>& initial_states) {
    return forward_for(initial_states, detail::SweepKind::Lone);
  }

  /// Batch-mean loss of a rollout of `initial_states` (state_dim × B) without storing the
  /// trajectory: memory O(B·(state_dim + network widths)) whatever the horizon, for large sets.
  /// Leaves the stored trajectory untouched; a non-finite value is reported through
  /// `forward_non_finite()` like in `forward`. Chunks of `kEvaluateChunk` samples are rolled
  /// out independently (in parallel with threads).
  Scalar evaluate(const Matrix<Scalar>& initial_states) {
    check_initial_states(initial_states, "evaluate");
    packed_controller_.pack();
    return evaluation_.run(sim_, packed_controller_, objective_, steps_, initial_states,
                           pool_.get(), forward_non_finite_);
  }

  /// Reverse sweep over the stored trajectory. Sets `gradient` (num_params) to the vector of
  /// the chosen schedule and returns the sweep's diagnostics.
  /// \param truncation window K (0 = none): no gradient crosses x_n for n a positive
  ///        multiple of K.
  const SweepDiagnostics& reverse(const FlowSchedule& schedule, Vector<Scalar>& gradient,
                                  Index truncation = 0) {
    check_sweep(schedule, truncation);
    const bool ends_batch = batch_threading_.claim_end(detail::SweepKind::Lone);
    const detail::LonePlan plan = lone_plan();
    const bool threaded = batch_threading_.lone_sweep_threaded(plan.meets_threads);
    if constexpr (SplitBackwardController<Ctrl>) {
      if (threaded && plan.handoff) {
        Handoff& h = *handoff_;
        auto add = [&](std::size_t slot) {
          detail::ReverseSweeps::add_params(*this, h, slot, gradient);
        };
        h.run(*pool_, steps_, add, [&] {
          detail::ReverseSweeps::lone(*this, sweeps_[0], schedule, gradient, truncation, false,
                                      &h);
        });
        if (ends_batch) finish_batch(detail::SweepKind::Lone);
        return sweeps_[0].diagnostics;
      }
    }
    detail::ReverseSweeps::lone(*this, sweeps_[0], schedule, gradient, truncation, threaded,
                                nullptr);
    if (ends_batch) finish_batch(detail::SweepKind::Lone);
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
  /// (shared_seed_sweeps.hpp); otherwise, with threads, the two sweeps run at the same time,
  /// each exactly as it would alone, and on one thread they go step by step together.
  void regular_and_modified(const Matrix<Scalar>& initial_states, GradientPair<Scalar>& result,
                            Index truncation = 0) {
    result.loss = forward_for(initial_states, detail::SweepKind::Pair);
    result.forward_non_finite = forward_non_finite_;
    check_sweep(FlowMode::Full, truncation);
    if constexpr (SeedScalingController<Ctrl>) {
      if (shares_seed()) {
        const bool ends_batch = batch_threading_.claim_end(detail::SweepKind::Pair);
        shared_seed_.run(*this, result, truncation, batch_threading_.threaded());
        if (ends_batch) finish_batch(detail::SweepKind::Pair);
        finish_pair(result);
        return;
      }
    }
    if (pool_) {
      auto task = [&](Index item, Index) {
        if (item == 0) {
          detail::ReverseSweeps::lone(*this, sweeps_[0], FlowMode::Full, result.regular,
                                      truncation, false, nullptr);
        } else {
          detail::ReverseSweeps::lone(*this, sweeps_[1], FlowMode::PhysicsOnly, result.modified,
                                      truncation, false, nullptr);
        }
      };
      pool_->run(2, task);
    } else {
      detail::ReverseSweeps::pair_in_step(*this, result, truncation);
    }
    finish_pair(result);
  }

private:
  using Scratch = detail::SampleScratch<State, Control>;
  using Sweep = detail::SweepBuffers<Scalar, Scratch>;
  using Evaluation = detail::ChunkedEvaluation<Scalar, typename Ctrl::Workspace, Scratch>;

  using Controller = Ctrl;
  using Handoff = typename detail::ParamHandoffOf<Ctrl>::Type;
  friend struct detail::ReverseSweeps;
  template <class Adjoints, class S>
  friend class detail::SharedSeedSweeps;
  template <class S>
  friend class detail::ForwardInParts;

  void check_initial_states(const Matrix<Scalar>& initial_states, const char* caller) const {
    detail::require(initial_states.rows() == sim_.state_dim(), "Engine::", caller, ": ",
                    initial_states.rows(), " rows in the initial states; expected state_dim = ",
                    sim_.state_dim());
    detail::require(initial_states.cols() > 0, "Engine::", caller,
                    ": an empty batch; expected at least one sample");
  }

  void check_sweep(const FlowSchedule& schedule, Index truncation) const {
    detail::require(trajectory_stored_,
                    "Engine::reverse: no stored trajectory; call forward first");
    detail::require(truncation >= 0, "Engine::reverse: truncation = ", truncation,
                    "; expected 0 (none) or a window of at least 1 step");
    schedule.validate(steps_);
  }

  [[nodiscard]] detail::LonePlan lone_plan() const {
    return detail::lone_plan<BatchSimulator<Sim>>(fork_[1], pool_ != nullptr,
                                                  handoff_ != nullptr);
  }
  /// Whether the pair shares one backward pass and, with threads, splits its steps.
  [[nodiscard]] bool shares_seed() const {
    return SeedScalingController<Ctrl> && sim_.control_dim() == 1;
  }

  /// `forward`, for a batch whose sweep of kind `kind` follows: the whole batch, this rollout
  /// included, goes the way of that kind's decision when the sweep would meet the other thread
  /// at every step, or, for a lone sweep, when the decision says `Never` (batch_threading.hpp).
  Scalar forward_for(const Matrix<Scalar>& initial_states, detail::SweepKind kind) {
    check_initial_states(initial_states, "forward");
    trajectory_stored_ = false;  // until this rollout ends: one that throws leaves none to sweep
    const Scalar loss = roll_out_for(initial_states, kind);
    trajectory_stored_ = true;
    return loss;
  }

  /// The rollout of `forward_for` into the trajectory, its batch loss returned.
  Scalar roll_out_for(const Matrix<Scalar>& initial_states, detail::SweepKind kind) {
    const bool decided =
        pool_ != nullptr && (kind == detail::SweepKind::Lone
                                 ? batch_threading_.decides_lone(lone_plan().meets_threads)
                                 : shares_seed());
    const Index batch = initial_states.cols();
    const bool threaded = batch_threading_.begin(kind, decided, batch);
    trajectory_.resize(steps_, sim_.state_dim(), sim_.control_dim(), batch);
    forward_non_finite_.reset();
    trajectory_.states[0] = initial_states;
    packed_controller_.pack();
    if constexpr (ColumnSplitController<Ctrl>) {
      if (pool_ && batch > 1 && threaded) {
        forward_in_parts_.run(*this, std::min(threads_, batch));
        return batch_loss();
      }
    }
    note_non_finite(Quantity::State, 0, trajectory_.states[0]);
    for (Index n = 0; n < steps_; ++n) {
      const auto i = static_cast<std::size_t>(n);
      packed_controller_.forward(trajectory_.states[i], trajectory_.controls[i],
                                 trajectory_.workspaces[i]);
      note_non_finite(Quantity::Control, n, trajectory_.controls[i]);
      detail::step_columns(sim_, trajectory_.states[i], trajectory_.controls[i],
                           trajectory_.states[i + 1], [&](auto&& body) {
        fork_[0].for_samples(pool_.get(), batch, forward_scratch_, threaded, body);
      });
      note_non_finite(Quantity::State, n + 1, trajectory_.states[i + 1]);
    }
    return batch_loss();
  }

  /// The layer adjoints of sweep `s` when it adds its own parameter products. The first
  /// sweep's are the hand-off's first slot where there is a hand-off: a batch on the threads
  /// sizes that slot, so that a batch run alone after it allocates nothing (the two never run
  /// at once).
  template <class SweepBuffers>
  auto& own_adjoints(const SweepBuffers& s) {
    if constexpr (SplitBackwardController<Ctrl>) {
      if (&s == &sweeps_[1]) return sweep_adjoints_[1];
      return handoff_ ? handoff_->ring[0] : sweep_adjoints_[0];
    } else {
      return sweep_adjoints_[0];
    }
  }

  /// The end of the current batch, to the decision of kind `kind`.
  void finish_batch(detail::SweepKind kind) {
    batch_threading_.finish(kind, trajectory_.batch());
  }

  void finish_pair(GradientPair<Scalar>& result) const {
    result.regular_diagnostics = sweeps_[0].diagnostics;
    result.modified_diagnostics = sweeps_[1].diagnostics;
    result.comparison =
        compare_and_combine(result.modified, result.regular, result.combined);
  }

  /// Batch-mean loss of the stored trajectory.
  Scalar batch_loss() {
    const Index batch = trajectory_.batch();
    const Scalar w = static_cast<Scalar>(objective_.step_weight);
    const Index first = objective_.timing == LossTiming::Final ? steps_ : 1;
    sample_losses_.setZero(batch);
    loss_steps_.setConstant(batch, steps_);
    fork_[2].for_samples(pool_.get(), batch, forward_scratch_, batch_threading_.threaded(),
                         [&](Index b, Scratch& t) {
      for (Index n = first; n <= steps_; ++n) {
        t.x = trajectory_.states[static_cast<std::size_t>(n)].col(b);
        const Scalar term = w * objective_.state_loss(t.x, static_cast<State*>(nullptr));
        sample_losses_(b) += term;
        if (loss_steps_(b) == steps_ && !std::isfinite(term)) loss_steps_(b) = n;
      }
      if (objective_.control_weight > 0) {
        Scalar squares = 0;
        for (const auto& c : trajectory_.controls) squares += c.col(b).squaredNorm();
        sample_losses_(b) += static_cast<Scalar>(objective_.control_weight /
                                                 static_cast<double>(steps_ * sim_.control_dim())) *
                             squares;
      }
    });
    return detail::mean_of_samples(sample_losses_, loss_steps_, forward_non_finite_);
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
  typename detail::SharedSeedSweepsOf<Ctrl>::Type shared_seed_;  ///< one control: shared pass
  detail::PackedController<Ctrl> packed_controller_{controller_};

  Trajectory<Scalar, typename Ctrl::Workspace> trajectory_;
  bool trajectory_stored_ = false;  ///< a forward pass ended and stored `trajectory_`
  std::optional<NonFinite> forward_non_finite_;
  std::vector<Scratch> forward_scratch_;
  detail::ForwardInParts<Scalar> forward_in_parts_;  ///< `forward` on several threads
  detail::ForkDecision fork_[3];  ///< per-sample loops: simulator step, VJPs, batch loss
  /// The way of the current batch, and the decisions that choose it.
  detail::BatchThreading batch_threading_;
  Sweep sweeps_[2];
  /// Each sweep's layer adjoints when it adds its own parameter products (`own_adjoints`).
  typename detail::LayerAdjointsOf<Ctrl>::Type sweep_adjoints_[2];
  /// Both sweeps' VJPs in one `vjp_batch` call, for a simulator without `vjp_batch_pair`.
  detail::PairedColumns<Scalar> paired_columns_;
  Evaluation evaluation_;
  Vector<Scalar> sample_losses_;  ///< `batch_loss`'s
  detail::LossSteps loss_steps_;  ///< and where each went non-finite
  // Last, so that it is destroyed first: its workers stop before the buffers they work on go.
  std::unique_ptr<detail::ThreadPool> pool_;
};

}  // namespace sbptt
