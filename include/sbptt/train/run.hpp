#pragma once
/// \file The training driver: a whole run of a `Trainer` over epochs, with an evaluation
/// schedule, per-epoch callbacks, an appended CSV log, best-parameter tracking, a patience
/// stop, checkpoints with bitwise resume, and the parameters saved at the end whatever
/// happened (docs/training.md).
///
/// Order of work in epoch e (each step only when configured):
/// 1. `Trainer::train_epoch`, evaluating when e is a multiple of `evaluate_every` or the last;
/// 2. non-finite events go to `on_non_finite`; a stop ends the run (`RunEnd::NonFinite`) with
///    the parameters from before epoch e;
/// 3. the best loss so far is updated (test loss, or train loss without a test set);
/// 4. the row is appended to the log, then `on_epoch` is called;
/// 5. a checkpoint is written when e is a multiple of `checkpoint_every`, when
///    `checkpoint_seconds` have passed since the last one, when the run stops early (patience,
///    `should_stop`), and after the last epoch (not after a non-finite stop: the checkpoint
///    before it stays);
/// 6. the run stops early after `patience` evaluations without a better loss.
/// With `evaluate_beside`, an evaluated epoch e (but the last) is evaluated on a second thread
/// while epoch e+1 trains; steps 2 to 6 of epoch e follow, then those of e+1 unless e ended
/// the run, in which case e+1 is undone (docs/training.md).
/// At the end the parameters (the best ones with `restore_best`) are saved, also after a
/// non-finite stop or a failed log write (`RunEnd::OutputFailed`): one failed output never
/// loses the trained parameters.
///
/// Resuming: when `checkpoint` names an existing file, the run continues from it after
/// checking that it was made with the same settings (`RunSetting`s: the trainer's options,
/// the optimizer's, fingerprints of the data and of the initial parameters, and the caller's
/// `identity`); the log is cut back to its size at that checkpoint. The result is bitwise the
/// one of an uninterrupted run (the seconds column aside, which is wall time). `epochs` is not
/// part of the identity: a finished run can be continued with a larger `epochs`; a smaller
/// one than the checkpoint's is refused. A run holds its checkpoint's lock
/// (`lock_checkpoint`) from before it reads the checkpoint to its end.
#include <sys/stat.h>

#include <cerrno>
#include <chrono>
#include <concepts>
#include <exception>
#include <functional>
#include <type_traits>
#include <utility>
#include <optional>
#include <string>
#include <tuple>
#include <vector>

#include "sbptt/core/atomic_file.hpp"
#include "sbptt/core/descriptor_limit.hpp"
#include "sbptt/core/file_identity.hpp"
#include "sbptt/nn/parameters_io.hpp"
#include "sbptt/train/checkpoint.hpp"
#include "sbptt/train/evaluation_beside.hpp"
#include "sbptt/train/fingerprint.hpp"
#include "sbptt/train/run_identity.hpp"
#include "sbptt/train/run_settings.hpp"
#include "sbptt/train/trainer.hpp"
#include "sbptt/train/trainer_state.hpp"
#include "sbptt/train/training_log.hpp"

namespace sbptt {

namespace detail {

/// The log that `settings.checkpoint` was written beside, checked for resuming after epoch
/// `rows` (its first `size` bytes) and not yet cut (`TrainingLogFile::open_for_resume`).
/// Throws `IoError` naming the log's setting by the caller's name; for a log that does not
/// exist (deleted, or another path given) it says that the checkpoint needs its own.
inline TrainingLogFile open_resumed_log(const RunSettings& settings, long long size, long rows) {
  const std::string name = caller_name(settings.setting_names, "log_csv");
  struct stat info {};
  if (::stat(settings.log_csv.c_str(), &info) != 0 && errno == ENOENT)
    throw IoError(concat(name, " '", settings.log_csv, "': ", os_reason(ENOENT), "; checkpoint '",
                         settings.checkpoint, "' continues the training log it was written "
                         "beside (epochs 1 to ", rows, "); expected ", name, " to name that log, "
                         "or no checkpoint to start over"));
  try {
    return TrainingLogFile::open_for_resume(settings.log_csv, size, rows);
  } catch (const IoError& e) {
    throw IoError(concat(name, " '", settings.log_csv, "': ", e.what()));
  }
}

/// `work()`, its errors prefixed with the caller's name for the checkpoint where it has one
/// (a program's flag): the checkpoint's own messages name its file, not the flag that gave it.
template <class Work>
decltype(auto) naming_checkpoint(const RunSettings& settings, Work&& work) {
  const std::string name = caller_name(settings.setting_names, "checkpoint");
  if (name == "checkpoint") return work();
  return prefixing_errors(name, std::forward<Work>(work));
}

}  // namespace detail

/// Runs `trainer` from its current state (or from `settings.checkpoint`) to `settings.epochs`
/// on `train` (state_dim × N, N ≥ 1) and `test` (state_dim × M; M = 0: no test set).
/// Throws before any work for bad settings (`InvalidArgument`), unwritable or colliding
/// outputs (`IoError`) and a checkpoint of another run (`InvalidArgument` naming the setting;
/// also one made without a training log resumed with one, and one made beside a log resumed
/// without it before its last epoch).
template <class TrainerT>
RunResult<typename TrainerT::Scalar> run_training(TrainerT& trainer,
                                                  const Matrix<typename TrainerT::Scalar>& train,
                                                  const Matrix<typename TrainerT::Scalar>& test,
                                                  const RunSettings& settings,
                                                  const RunCallbacks& callbacks = {}) {
  using Scalar = typename TrainerT::Scalar;
  using Optimizer = std::remove_cvref_t<decltype(trainer.optimizer())>;
  using Ctrl = std::remove_cvref_t<decltype(trainer.controller())>;
  trainer.check_sets(train, test, "run_training");
  // A NaN here stopped the first batch, and the save of such parameters then failed too.
  if (const auto at = first_non_finite(trainer.controller().params()))
    throw InvalidArgument(detail::concat(
        "run_training: the controller's parameter ", at->row, " is ",
        detail::value_text(static_cast<double>(trainer.controller().params()(at->row))),
        "; expected finite initial parameters"));
  detail::require(settings.epochs >= 0, "run_training: epochs = ", settings.epochs,
                  "; expected >= 0");
  detail::require(settings.evaluate_every >= 1, "run_training: evaluate_every = ",
                  settings.evaluate_every, "; expected >= 1");
  detail::require(settings.patience >= 0, "run_training: patience = ", settings.patience,
                  "; expected >= 0 (0 = no early stop)");
  detail::require(settings.checkpoint_every >= 0, "run_training: checkpoint_every = ",
                  settings.checkpoint_every, "; expected >= 0");
  detail::require(settings.checkpoint_seconds >= 0, "run_training: checkpoint_seconds = ",
                  settings.checkpoint_seconds, "; expected >= 0");
  const BestBy best_by = settings.best_by.value_or(test.cols() > 0 ? BestBy::TestLoss
                                                                   : BestBy::TrainLoss);
  detail::require(best_by == BestBy::TrainLoss || test.cols() > 0,
                  "run_training: best_by = test loss without a test set; expected a test set "
                  "or BestBy::TrainLoss");
  if constexpr (!std::copy_constructible<Ctrl>) {
    detail::require(!settings.evaluate_beside, "run_training: evaluate_beside needs a copy of "
                                               "the controller; expected a copyable controller");
  }
  if constexpr (!detail::AdamLike<Optimizer>) {
    detail::require(settings.checkpoint.empty(), "run_training: checkpoints need an optimizer "
                                                 "whose state can be saved (Adam)");
  }
  auto& params = trainer.controller().params();
  const TrainerOptions& o = trainer.options();
  const std::vector<RunSetting> identity =
      detail::run_identity(trainer, train, test, settings, best_by);
  std::vector<std::string> outputs;  // by the caller's names
  for (const auto& [what, setting, path] :
       {std::tuple{"training log", "log_csv", &settings.log_csv},
        std::tuple{"checkpoint", "checkpoint", &settings.checkpoint},
        std::tuple{"parameters file", "save_params", &settings.save_params}}) {
    if (path->empty()) continue;
    check_output_path(*path, what);
    outputs.push_back(caller_name(settings.setting_names, setting));
  }
  // The lock too (never written, so an input beside it is no clash): a log renamed over it
  // would leave a second run of the checkpoint a lock of its own.
  require_distinct_files({{"training log", settings.log_csv, true},
                          {"checkpoint", settings.checkpoint, true},
                          {"parameters file", settings.save_params, true},
                          {"checkpoint's lock file", checkpoint_lock_path(settings.checkpoint),
                           false}});
  detail::require_descriptors_for_outputs(outputs, !settings.log_csv.empty(),
                                          !settings.checkpoint.empty());
  const detail::FileLock checkpoint_lock =
      detail::naming_checkpoint(settings, [&] { return lock_checkpoint(settings.checkpoint); });

  // Before the log or a checkpoint is touched: it refuses a controller whose copy would share
  // the parameters.
  std::optional<EvaluationBeside<TrainerT>> beside;
  if constexpr (std::copy_constructible<Ctrl>) {
    if (settings.evaluate_beside) beside.emplace(trainer);
  }

  RunResult<Scalar> result;
  long since_best = 0;
  std::optional<TrainingLogFile> log;
  std::optional<Checkpoint<Scalar>> resumed;
  if (!settings.checkpoint.empty()) {
    resumed = detail::naming_checkpoint(settings, [&] {
      return load_checkpoint<Scalar>(settings.checkpoint, [&](const auto& found) {
        require_same_settings(identity, found, settings.checkpoint, settings.setting_names);
      });
    });
  }
  if (resumed) {
    detail::naming_checkpoint(settings, [&] {
      detail::require<ParseError>(resumed->params.size() == params.size(), "checkpoint '",
                                  settings.checkpoint, "' has ", resumed->params.size(),
                                  " parameters; expected ", params.size());
      // Resumed, it would end at once and hand back the parameters of the later epoch as if
      // they were those of `epochs`.
      const std::string epochs = caller_name(settings.setting_names, "epochs");
      detail::require(resumed->epoch <= settings.epochs, "checkpoint '", settings.checkpoint,
                      "' is at epoch ", resumed->epoch, ", past ", epochs, " = ",
                      settings.epochs, "; expected ", epochs, " >= ", resumed->epoch,
                      " (a run is not wound back: for ", settings.epochs,
                      " epochs, start without this checkpoint)");
      // Settings of the run that differ, like those above: refused before the resume begins.
      const std::string log_name = caller_name(settings.setting_names, "log_csv");
      detail::require(settings.log_csv.empty() || resumed->log_bytes >= 0, "checkpoint '",
                      settings.checkpoint, "' was made without a training log, and this run "
                      "has ", log_name, " '", settings.log_csv, "'; expected no ", log_name,
                      " (the log would lack epochs 1 to ", resumed->epoch, "), or no "
                      "checkpoint to start over");
      // A finished run rerun without its log trains nothing, so its log lacks nothing.
      detail::require(!settings.log_csv.empty() || resumed->log_bytes < 0 ||
                          resumed->epoch == settings.epochs,
                      "checkpoint '", settings.checkpoint, "' was made beside a training log "
                      "(epochs 1 to ", resumed->epoch, "), and this run has no ", log_name,
                      ": the log would stop at epoch ", resumed->epoch, " while training goes "
                      "on; expected ", log_name, " to name that log, or no checkpoint to start "
                      "over");
      if constexpr (detail::AdamLike<Optimizer>) {
        // From a fresh trainer Adam takes at most one step a batch (fewer with skipped
        // batches, or a callback that resets it): more would resume with bias corrections the
        // run never had. A trainer that had trained before this call has counts of its own.
        const long long batches = (train.cols() + o.batch - 1) / o.batch;
        detail::require<ParseError>(resumed->skipped_batches <= resumed->epoch * batches,
                                    "checkpoint '", settings.checkpoint, "': skipped_batches ",
                                    resumed->skipped_batches, " after ", resumed->epoch,
                                    " epochs of ", batches, " batches; expected at most ",
                                    resumed->epoch * batches);
        const long long steps = resumed->epoch * batches - resumed->skipped_batches;
        detail::require<ParseError>(
            trainer.epoch() > 0 || resumed->adam_t <= steps, "checkpoint '",
            settings.checkpoint, "': adam_t ", resumed->adam_t, " after ", resumed->epoch,
            " epochs of ", batches, " batches, ", resumed->skipped_batches,
            " of them skipped; expected at most ", steps, " (one step a batch)");
      }
    });
    if (!settings.log_csv.empty())
      log = detail::open_resumed_log(settings, resumed->log_bytes, resumed->epoch);
    if constexpr (detail::AdamLike<Optimizer>)
      trainer.optimizer().restore(resumed->adam_m, resumed->adam_v, resumed->adam_t);
    trainer.resume_at(resumed->epoch, resumed->shuffle_state);
    params = resumed->params;
    result.resumed_from = resumed->epoch;
    result.epochs = resumed->epoch;
    result.last = resumed->last;
    result.best_epoch = resumed->best_epoch;
    result.best_loss = resumed->best_loss;
    result.best_params = resumed->best_params;
    result.skipped_batches = resumed->skipped_batches;
    since_best = resumed->since_best;
    if (log) log->cut_back();
    if (callbacks.on_resume) callbacks.on_resume(resumed->epoch);
  } else if (!settings.log_csv.empty()) {
    log = TrainingLogFile::create(settings.log_csv);
  }
  if (callbacks.on_start) callbacks.on_start(result.epochs);

  // The trainer's state after an epoch, for its checkpoint: the live one, or (with the
  // evaluation beside) the one kept when the next epoch began.
  using State = detail::TrainerState<Scalar, Optimizer>;
  auto write_checkpoint = [&](const State* kept) {
    Checkpoint<Scalar> c;
    c.settings = identity;
    c.epoch = result.epochs;
    c.shuffle_state = kept ? kept->shuffle_state : trainer.shuffle_state();
    if (log) {
      log->sync();
      c.log_bytes = log->size();
    }
    c.skipped_batches = result.skipped_batches;
    c.since_best = since_best;
    c.best_epoch = result.best_epoch;
    c.best_loss = result.best_loss;
    c.last = result.last;
    c.params = kept ? kept->params : params;
    c.best_params = result.best_params;
    if constexpr (detail::AdamLike<Optimizer>) {
      const Optimizer& adam = kept ? kept->optimizer : trainer.optimizer();
      c.adam_t = adam.iterations();
      c.adam_m = adam.first_moment();
      c.adam_v = adam.second_moment();
    }
    save_checkpoint(settings.checkpoint, c);
  };

  using Clock = std::chrono::steady_clock;
  auto last_checkpoint = Clock::now();
  // Steps 2 to 6 of the file comment for the epoch of `record`, trained and evaluated, which
  // met `events` and ended training when `stopped`. True when the run ends with it.
  auto conclude = [&](const EpochRecord& record, bool evaluated,
                      const std::vector<NonFiniteEvent>& events, bool stopped,
                      const State* kept) {
    for (const NonFiniteEvent& event : events) {
      const bool skipped =
          event.phase == Phase::Update && o.on_non_finite == NonFinitePolicy::SkipBatch;
      // A stopped epoch is undone, like its count of skipped batches.
      if (skipped && !stopped) ++result.skipped_batches;
      if (callbacks.on_non_finite) callbacks.on_non_finite(event, skipped);
    }
    if (stopped) {
      result.end = RunEnd::NonFinite;
      result.stop_event = events.back();
      return true;
    }
    result.epochs = record.epoch;
    result.last = record;
    if (evaluated) {
      const double loss = *(best_by == BestBy::TestLoss ? record.test_loss : record.train_loss);
      if (result.best_epoch == 0 || loss < result.best_loss) {
        result.best_epoch = record.epoch;
        result.best_loss = loss;
        result.best_params = kept ? kept->params : params;
        since_best = 0;
      } else {
        ++since_best;
      }
    }
    bool stop = false;
    try {
      if (log) log->append(record);
      if (callbacks.on_epoch) callbacks.on_epoch(record);
      stop = callbacks.should_stop && callbacks.should_stop(record);
      // A stop asked for in the last epoch cuts nothing: the run has finished.
      if (stop && record.epoch < settings.epochs) result.end = RunEnd::Requested;
      if (settings.patience > 0 && since_best >= settings.patience) {
        result.end = RunEnd::EarlyStop;
        stop = true;
      }
      const bool due =
          (settings.checkpoint_every > 0 && record.epoch % settings.checkpoint_every == 0) ||
          (settings.checkpoint_seconds > 0 &&
           std::chrono::duration<double>(Clock::now() - last_checkpoint).count() >=
               settings.checkpoint_seconds) ||
          record.epoch == settings.epochs || stop;
      if (!settings.checkpoint.empty() && due) {
        write_checkpoint(kept);
        last_checkpoint = Clock::now();
      }
    } catch (const IoError& e) {
      result.end = RunEnd::OutputFailed;
      result.output_error = e.what();
      return true;
    }
    return stop;
  };

  // With the evaluation beside, an evaluated epoch (but the last) waits as `pending` while the
  // next one trains without its own evaluation: that next epoch is ahead of the run, and is
  // undone when the pending epoch ends the run.
  struct Pending {
    EpochRecord record;
    std::vector<NonFiniteEvent> events;
    State before, after;  ///< the trainer before and after the epoch's training
  };
  std::optional<Pending> pending;
  const bool patience_spent = settings.patience > 0 && since_best >= settings.patience;
  if (patience_spent) result.end = RunEnd::EarlyStop;
  for (long epoch = trainer.epoch() + 1; epoch <= settings.epochs && !patience_spent; ++epoch) {
    const bool evaluate = epoch % settings.evaluate_every == 0 || epoch == settings.epochs;
    const bool ahead = beside && evaluate && epoch < settings.epochs;
    // The state before an epoch trained ahead: the pending epoch's `after` when there is one,
    // taken over once that epoch is concluded.
    std::optional<State> before;
    if (ahead && !pending) before = detail::state_of(trainer);
    EpochRecord record;
    auto train_this_epoch = [&] { record = trainer.train_epoch(train, test, evaluate && !ahead); };
    if (pending) {
      // Without the look-ahead the pending epoch ends before this one starts, and may end the
      // run: an exception of this epoch's training waits for that end.
      std::exception_ptr training_failure;
      const std::size_t update_events = pending->events.size();
      try {
        beside->run(pending->after.params, train, test, pending->record, pending->events, [&] {
          try {
            train_this_epoch();
          } catch (...) {
            training_failure = std::current_exception();
          }
        });
      } catch (...) {  // from the evaluation, where the pending epoch's own would have thrown
        detail::restore_trainer(trainer, pending->after);
        throw;
      }
      // As in `Trainer::train_epoch`: a non-finite evaluation ends training and rolls its
      // epoch back.
      const bool stopped = pending->events.size() > update_events;
      auto rewind = [&] {
        detail::restore_trainer(trainer, pending->after);
        if (stopped) detail::restore_parameters_and_optimizer(trainer, pending->before);
      };
      bool ends = false;
      try {
        ends = conclude(pending->record, true, pending->events, stopped, &pending->after);
      } catch (...) {
        rewind();
        throw;
      }
      if (ends) rewind();
      if (ahead && !ends) before = std::move(pending->after);
      pending.reset();
      if (ends) break;
      if (training_failure) std::rethrow_exception(training_failure);
    } else {
      train_this_epoch();
    }
    if (ahead && !trainer.stopped()) {
      pending = Pending{record, trainer.non_finite_events(), std::move(*before),
                        detail::state_of(trainer)};
      continue;
    }
    if (conclude(record, evaluate, trainer.non_finite_events(), trainer.stopped(), nullptr))
      break;
  }
  if (log && result.end != RunEnd::OutputFailed) {
    try {
      log->sync();
      detail::sync_directory(detail::directory_of(detail::final_target(log->path())),
                             log->path());
    } catch (const IoError& e) {
      result.end = RunEnd::OutputFailed;
      result.output_error = e.what();
    }
  }
  if (settings.restore_best && result.best_epoch > 0) params = result.best_params;
  if (!settings.save_params.empty()) {
    try {
      save_parameters(settings.save_params, params);
      result.saved_params = settings.save_params;
    } catch (const Error& e) {
      if (result.end != RunEnd::OutputFailed) result.end = RunEnd::OutputFailed;
      if (!result.output_error.empty()) result.output_error += "; ";
      result.output_error += e.what();
    }
  }
  return result;
}

}  // namespace sbptt
