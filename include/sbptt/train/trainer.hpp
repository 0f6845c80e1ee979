#pragma once
/// \file The training epoch: mini-batches in a fixed order (as the reference) or reshuffled,
/// one update per batch with the chosen method, then (unless the caller skips it) an
/// evaluation of the whole train set and of the test set, if there is one. A whole run with
/// its log, schedule and checkpoints is `run_training` (train/run.hpp).
///
/// Update of one mini-batch:
/// - R, M, S, N: one forward pass, one sweep of that mode, clip, optimizer step;
/// - C: one forward pass, the Full and PhysicsOnly sweeps over it, combine, clip, step.
///
/// Non-finite values: the batch's forward pass, its sweep(s), the stepped parameters and the
/// epoch's evaluation of the train and test sets are checked. In C mode a non-finite g_R is
/// not an error: its NaN components fail the sign test and drop out, as in the reference.
/// A non-finite batch leaves the parameters and the optimizer state (Adam's m, v, t) as they
/// were before it, and is recorded; `NonFinitePolicy` chooses whether training stops there
/// (Stop) or goes on with the next batch (SkipBatch). Training also stops, whatever the
/// policy, when the evaluation is non-finite or when no batch of the epoch was finite.
/// A stop rolls parameters and optimizer back to the start of the epoch: the last parameters
/// whose evaluation was finite (a mid-epoch state was never evaluated, so it is not kept).
#include <chrono>
#include <cmath>
#include <numeric>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "sbptt/bptt/engine.hpp"
#include "sbptt/bptt/sweep_threading.hpp"
#include "sbptt/core/non_finite.hpp"
#include "sbptt/core/rng.hpp"
#include "sbptt/optim/clip.hpp"
#include "sbptt/optim/combined_update.hpp"
#include "sbptt/train/method.hpp"
#include "sbptt/train/training_log.hpp"

namespace sbptt {

/// What to do when a batch produces a NaN or Inf.
enum class NonFinitePolicy { Stop, SkipBatch };

/// Settings of a training run besides the optimizer.
struct TrainerOptions {
  Method method = Method::Combined;
  ClipMode clip = ClipMode::None;
  double clip_threshold = 1.0;
  Index batch = 8;
  bool shuffle = false;           ///< reshuffle the train set every epoch (the reference does not)
  std::uint64_t shuffle_seed = 0;
  Index truncation = 0;           ///< window K of the reverse sweep; 0 = none
  NonFinitePolicy on_non_finite = NonFinitePolicy::Stop;
  /// Threads of the engine (≥ 1, see `Engine::set_threads`): per-sample simulator work, the
  /// two sweeps of C at once (or, with one control, their shared backward passes split by
  /// steps), and the evaluation in chunks. Results are bitwise identical for every thread
  /// count.
  Index threads = 1;
  /// With threads, whether a batch whose sweep meets the other thread at every step uses them
  /// (`SweepThreading`; by default timed against one thread now and then).
  SweepThreading sweep_threading = SweepThreading::Timed;
};

/// The part of an epoch that met a non-finite value.
enum class Phase { Update, TrainEvaluation, TestEvaluation };

[[nodiscard]] constexpr std::string_view to_string(Phase phase) {
  switch (phase) {
    case Phase::Update: return "update";
    case Phase::TrainEvaluation: return "train-set evaluation";
    case Phase::TestEvaluation: return "test-set evaluation";
  }
  return "?";
}

/// Where training met a non-finite value.
struct NonFiniteEvent {
  long epoch = 0;
  Index batch = 0;  ///< index of the mini-batch within the epoch; -1 in an evaluation
  /// Quantity, step and sample: the column of the set it came from (the train set's in an
  /// update, whatever the shuffle); for a gradient or a parameter, its index.
  NonFinite where;
  Phase phase = Phase::Update;
  /// The simulator's words for the calls it refused up to this event, when it gives them
  /// (`ExplainsRefusals`, e.g. MuJoCo's "contact buffer is full"); else empty.
  std::string cause;
};

/// ", step 9, sample 0", or ", parameter 3" for a gradient or a parameter.
[[nodiscard]] inline std::string describe_where(const NonFinite& where) {
  return where.quantity == Quantity::Gradient || where.quantity == Quantity::Parameter
             ? detail::concat(", parameter ", where.sample)
             : detail::concat(", step ", where.step, ", sample ", where.sample);
}

/// "non-finite state (inf) in epoch 2, batch 1, step 9, sample 0": the event in words, and
/// the simulator's cause after "; " when it gave one.
[[nodiscard]] inline std::string describe(const NonFiniteEvent& event) {
  const NonFinite& where = event.where;
  std::string text = detail::concat("non-finite ", to_string(where.quantity), " (",
                                    detail::value_text(where.value), ") in ");
  text += event.phase == Phase::Update
              ? detail::concat("epoch ", event.epoch, ", batch ", event.batch)
              : detail::concat("the ", to_string(event.phase), " of epoch ", event.epoch);
  text += describe_where(where);
  return text + detail::note_after("; ", event.cause);
}

namespace detail {

/// The event at `where`, with the cause that `sim` gives (see `ExplainsRefusals`).
template <class Sim>
[[nodiscard]] NonFiniteEvent non_finite_event(const Sim& sim, long epoch, Index batch,
                                              const NonFinite& where, Phase phase) {
  return {epoch, batch, where, phase, take_refusal_note(sim)};
}

/// The evaluation of an epoch: the mean loss of `train`, and of `test` unless it is empty,
/// into `record`; each non-finite rollout goes to `note` as an event of `record.epoch`.
template <class EngineT, class Scalar, class Note>
void evaluate_sets(EngineT& engine, const Matrix<Scalar>& train, const Matrix<Scalar>& test,
                   EpochRecord& record, Note&& note) {
  auto loss_of = [&](const Matrix<Scalar>& set, Phase phase) {
    const auto loss = static_cast<double>(engine.evaluate(set));
    if (engine.forward_non_finite())
      note(non_finite_event(engine.simulator(), record.epoch, -1, *engine.forward_non_finite(),
                            phase));
    return loss;
  };
  record.train_loss = loss_of(train, Phase::TrainEvaluation);
  if (test.cols() > 0) record.test_loss = loss_of(test, Phase::TestEvaluation);
}

}  // namespace detail

template <class Sim, class Ctrl, class Loss, class Optimizer>
class Trainer {
public:
  using Scalar = typename Sim::Scalar;

  Trainer(const Sim& sim, Ctrl& controller, Objective<Loss> objective, Index steps,
          Optimizer optimizer, TrainerOptions options)
      : controller_(controller),
        state_dim_(sim.state_dim()),
        engine_(sim, controller, std::move(objective), steps),
        options_(options),
        clipped_(optimizer, options.clip, static_cast<Scalar>(options.clip_threshold)),
        combined_(std::move(optimizer), options.clip, static_cast<Scalar>(options.clip_threshold)),
        saved_optimizer_(combined_.inner()),
        epoch_optimizer_(combined_.inner()),
        shuffle_rng_(options.shuffle_seed) {
    detail::require(options.batch > 0, "Trainer: batch = ", options.batch,
                    "; expected at least 1 sample per batch");
    detail::require(options.truncation >= 0, "Trainer: truncation = ", options.truncation,
                    "; expected 0 (none) or a window >= 1");
    detail::require(options.threads >= 1, "Trainer: threads = ", options.threads,
                    "; expected at least 1");
    engine_.set_threads(options.threads, Engine<Sim, Ctrl, Loss>::kDefaultSplitAboveNs,
                        options.sweep_threading);
  }

  /// The trainer keeps references to the simulator and the controller: binding a temporary
  /// is refused at compile time. (The objective and the optimizer are copied.)
  Trainer(const Sim&& temporary_simulator, Ctrl& controller, Objective<Loss> objective,
          Index steps, Optimizer optimizer, TrainerOptions options) = delete;
  Trainer(const Sim& sim, Ctrl&& temporary_controller, Objective<Loss> objective, Index steps,
          Optimizer optimizer, TrainerOptions options) = delete;
  Trainer(const Sim&& temporary_simulator, Ctrl&& temporary_controller,
          Objective<Loss> objective, Index steps, Optimizer optimizer,
          TrainerOptions options) = delete;

  /// One epoch over `train` (state_dim × N_train, N_train ≥ 1), then, when `evaluate`, the
  /// evaluation of `train` and of `test` (state_dim × N_test; N_test = 0 means no test set,
  /// and test_loss stays empty). Both sets are checked before any update. When `stopped()`
  /// afterwards, the record is not meaningful and the parameters are those from before the
  /// epoch.
  EpochRecord train_epoch(const Matrix<Scalar>& train, const Matrix<Scalar>& test,
                          bool evaluate = true) {
    check_sets(train, test, "Trainer::train_epoch");
    EpochRecord record;
    record.epoch = ++epoch_;
    events_.clear();
    stopped_ = false;
    // The simulator's refusals before the epoch (the caller's own evaluation, say) are no
    // cause of its events.
    (void)detail::take_refusal_note(engine_.simulator());
    epoch_params_ = controller_.params();
    epoch_optimizer_ = optimizer();
    order_.resize(static_cast<std::size_t>(train.cols()));
    std::iota(order_.begin(), order_.end(), Index{0});
    if (options_.shuffle) shuffle(order_);

    const auto start = std::chrono::steady_clock::now();
    const Index batches = (train.cols() + options_.batch - 1) / options_.batch;
    double loss_sum = 0, norm_sum = 0, cos_sum = 0, agree_sum = 0;
    Index done = 0;
    for (Index k = 0; k < batches; ++k) {
      gather(train, k, batch_states_);
      const std::optional<NonFinite> bad = update(batch_states_);
      if (bad) {
        note(detail::non_finite_event(engine_.simulator(), record.epoch, k, in_train_set(*bad, k),
                                      Phase::Update));
        if (options_.on_non_finite == NonFinitePolicy::Stop) break;
        continue;
      }
      ++done;
      loss_sum += static_cast<double>(last_loss_);
      norm_sum += last_norm2_;
      cos_sum += last_comparison_.cos_modified_regular;
      agree_sum += last_comparison_.agree_fraction;
    }
    record.seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (stopped_ || done == 0) return roll_back(record);
    const double per = 1.0 / static_cast<double>(done);
    record.batch_loss = loss_sum * per;
    record.update_norm2 = norm_sum * per;
    if (options_.method == Method::Combined) {
      record.cos_m_r = cos_sum * per;
      record.agree_fraction = agree_sum * per;
    }
    if (evaluate)
      detail::evaluate_sets(engine_, train, test, record, [&](const auto& e) { note(e); });
    return stopped_ ? roll_back(record) : record;
  }

  /// Epochs trained so far (the number of the last one).
  [[nodiscard]] long epoch() const { return epoch_; }
  /// The shuffling generator's state (for checkpoints; see `Rng::state`).
  [[nodiscard]] std::string shuffle_state() const { return shuffle_rng_.state(); }
  /// Continues a run from a checkpoint: the next epoch is `epoch` + 1 and the shuffling
  /// generator resumes from `shuffle_state`. The caller restores the parameters (in the
  /// controller) and the optimizer state (`optimizer()`).
  void resume_at(long epoch, const std::string& shuffle_state) {
    detail::require(epoch >= 0, "Trainer::resume_at: epoch = ", epoch, "; expected >= 0");
    detail::require(shuffle_rng_.restore(shuffle_state),
                    "Trainer::resume_at: the shuffling state is not a generator state");
    epoch_ = epoch;
  }

  /// The last non-finite event of any epoch so far, if there was one.
  [[nodiscard]] const std::optional<NonFiniteEvent>& last_non_finite() const {
    return last_non_finite_;
  }
  /// Every non-finite event of the last epoch, in order (the skipped batches, with SkipBatch).
  [[nodiscard]] const std::vector<NonFiniteEvent>& non_finite_events() const { return events_; }
  /// True when the last epoch ended training (see the file comment): its record is void and
  /// the parameters are those from before it.
  [[nodiscard]] bool stopped() const { return stopped_; }
  [[nodiscard]] Engine<Sim, Ctrl, Loss>& engine() { return engine_; }
  /// The controller being trained (its `params()` are the parameters θ).
  [[nodiscard]] Ctrl& controller() { return controller_; }
  /// The optimizer that takes the steps of the configured method (e.g. to change its rate).
  [[nodiscard]] Optimizer& optimizer() {
    return options_.method == Method::Combined ? combined_.inner() : clipped_.inner();
  }
  [[nodiscard]] const TrainerOptions& options() const { return options_; }

  /// Throws `InvalidArgument`, in `caller`'s name, unless `train` is state_dim × N with N ≥ 1
  /// and `test` state_dim × M (M = 0: no test set), all finite, as `train_epoch` needs them.
  void check_sets(const Matrix<Scalar>& train, const Matrix<Scalar>& test,
                  const char* caller) const {
    auto check = [&](const Matrix<Scalar>& set, const char* name, Index min_samples) {
      detail::require(set.cols() >= min_samples, caller, ": the ", name, " set has ", set.cols(),
                      " samples; expected at least ", min_samples);
      detail::require(set.cols() == 0 || set.rows() == state_dim_, caller, ": the ", name,
                      " set has ", set.rows(), " rows; expected the state dimension ",
                      state_dim_);
      if (const std::optional<EntryIndex> at = first_non_finite(set)) {
        throw InvalidArgument(detail::concat(caller, ": the ", name, " set has ",
                                             detail::value_text(set(at->row, at->column)),
                                             " in sample ", at->column,
                                             ", entry ", at->row,
                                             "; expected finite initial states"));
      }
    };
    check(train, "train", 1);
    check(test, "test", 0);
  }

private:
  void gather(const Matrix<Scalar>& set, Index k, Matrix<Scalar>& out) const {
    const Index first = k * options_.batch;
    const Index count = std::min(options_.batch, set.cols() - first);
    out.resize(set.rows(), count);
    for (Index j = 0; j < count; ++j)
      out.col(j) = set.col(order_[static_cast<std::size_t>(first + j)]);
  }

  void shuffle(std::vector<Index>& order) {
    for (std::size_t i = order.size(); i > 1; --i) {
      const auto j = static_cast<std::size_t>(shuffle_rng_.uniform() * static_cast<double>(i));
      std::swap(order[i - 1], order[std::min(j, i - 1)]);
    }
  }

  void note(const NonFiniteEvent& event) {
    events_.push_back(event);
    last_non_finite_ = event;
    if (event.phase != Phase::Update || options_.on_non_finite == NonFinitePolicy::Stop)
      stopped_ = true;
  }

  EpochRecord& roll_back(EpochRecord& record) {
    stopped_ = true;
    controller_.params() = epoch_params_;
    optimizer() = epoch_optimizer_;
    return record;
  }

  /// One optimizer step on one mini-batch; returns the first non-finite value, if any, in
  /// which case the parameters and the optimizer state are unchanged.
  std::optional<NonFinite> update(const Matrix<Scalar>& states) {
    backup_ = controller_.params();
    saved_optimizer_ = optimizer();
    std::optional<NonFinite> bad;
    if (options_.method == Method::Combined) {
      engine_.regular_and_modified(states, pair_, options_.truncation);
      last_loss_ = pair_.loss;
      bad = pair_.forward_non_finite ? pair_.forward_non_finite
                                     : pair_.modified_diagnostics.first_non_finite;
      if (!bad) {
        combined_.step_combined(controller_.params(), pair_.combined,
                                static_cast<Scalar>(pair_.comparison.agree_fraction));
        last_norm2_ = combined_.last_norm2();
        last_comparison_ = pair_.comparison;
      }
    } else {
      last_loss_ = engine_.forward(states);
      bad = engine_.forward_non_finite();
      if (!bad) {
        bad = engine_.reverse(*flow_mode(options_.method), gradient_, options_.truncation)
                  .first_non_finite;
      }
      if (!bad) {
        clipped_.step_in_place(controller_.params(), gradient_);
        last_norm2_ = clipped_.last_norm2();
      }
    }
    if (!bad) {
      bad = detail::first_non_finite_component(controller_.params(), Quantity::Parameter);
    }
    if (bad) {
      controller_.params() = backup_;
      optimizer() = saved_optimizer_;
    }
    return bad;
  }

  /// `where` with its sample made the train set's column, as an evaluation's is: the engine
  /// numbers the columns of batch `batch`, which after a shuffle name no column a user can find.
  [[nodiscard]] NonFinite in_train_set(NonFinite where, Index batch) const {
    const bool per_sample =
        where.quantity != Quantity::Gradient && where.quantity != Quantity::Parameter;
    if (per_sample && where.sample >= 0)
      where.sample = order_[static_cast<std::size_t>(batch * options_.batch + where.sample)];
    return where;
  }

  Ctrl& controller_;
  Index state_dim_;
  Engine<Sim, Ctrl, Loss> engine_;
  TrainerOptions options_;
  ClippedUpdate<Optimizer> clipped_;
  CombinedUpdate<Optimizer> combined_;
  Optimizer saved_optimizer_, epoch_optimizer_;  ///< before the batch, before the epoch
  Rng shuffle_rng_;
  long epoch_ = 0;
  std::vector<Index> order_;
  Matrix<Scalar> batch_states_;
  Vector<Scalar> gradient_, backup_, epoch_params_;
  GradientPair<Scalar> pair_;
  Scalar last_loss_ = 0;
  double last_norm2_ = 0;
  ComparisonDiagnostics last_comparison_;
  std::optional<NonFiniteEvent> last_non_finite_;
  std::vector<NonFiniteEvent> events_;
  bool stopped_ = false;
};

}  // namespace sbptt
