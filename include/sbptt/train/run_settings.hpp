#pragma once
/// \file What a run of `run_training` (run.hpp) is given and gives back: its settings, its
/// callbacks and its result (docs/training.md, "Settings and callbacks").
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "sbptt/core/types.hpp"
#include "sbptt/train/checkpoint.hpp"
#include "sbptt/train/trainer.hpp"
#include "sbptt/train/training_log.hpp"

namespace sbptt {

/// Which loss decides the best parameters.
enum class BestBy { TestLoss, TrainLoss };

/// Settings of a run besides those of the trainer.
struct RunSettings {
  long epochs = 1000;
  long evaluate_every = 1;         ///< evaluate every k-th epoch (k ≥ 1) and the last
  std::optional<BestBy> best_by{}; ///< default: the test loss, or the train loss without test set
  long patience = 0;               ///< stop after this many evaluations without improvement; 0 = never
  bool restore_best = false;       ///< end with the best parameters instead of the last
  std::string log_csv{};           ///< the training log; empty = none
  std::string checkpoint{};        ///< the checkpoint file; empty = none
  long checkpoint_every = 1;       ///< epochs between checkpoints; 0 = only by time and at the end
  double checkpoint_seconds = 0;   ///< also after this much wall time since the last; 0 = off
  std::string save_params{};       ///< where the final parameters go; empty = not saved
  /// Evaluate each evaluated epoch (but the last) on a second thread while the next epoch
  /// trains (train/evaluation_beside.hpp). The results, log, checkpoints and the trainer's
  /// parameters, optimizer, epoch and shuffling state are bitwise those without it (the
  /// seconds column aside), and either way resumes the other's checkpoints. The callbacks of
  /// epoch e run after epoch e+1 has trained, so the trainer they see is one epoch ahead: a
  /// callback that changes the trainer does not act as written (docs/training.md). A run that
  /// ends at epoch e undoes epoch e+1.
  bool evaluate_beside = false;
  /// Settings of the caller that a checkpoint must share (e.g. the task's flags).
  std::vector<RunSetting> identity{};
  /// The caller's names, in messages, for any setting the checkpoint compares and for
  /// "epochs", "log_csv", "checkpoint" and "save_params", as pairs {setting, caller's name} (e.g.
  /// {"shuffle_seed", "--seed"}); the others keep their own. A name for "checkpoint" leads
  /// every refusal of the checkpoint ("--checkpoint: checkpoint 'F' …").
  std::vector<RunSetting> setting_names{};
};

/// Hooks called during a run (each may be empty).
struct RunCallbacks {
  std::function<void(long epoch)> on_resume{};  ///< a checkpoint of `epoch` epochs was loaded
  std::function<void(const EpochRecord&)> on_epoch{};  ///< after the row of each epoch is logged
  /// Each non-finite event; `skipped` says that the batch was skipped. Training goes on unless
  /// the epoch then ends the run (`RunEnd::NonFinite`: no batch of it was finite, or its
  /// evaluation was not), which undoes the epoch.
  std::function<void(const NonFiniteEvent&, bool skipped)> on_non_finite{};
  /// Asked after each epoch; true ends the run (`RunEnd::Requested`) after its checkpoint,
  /// but for the last epoch, after which the run is `Finished` either way.
  std::function<bool(const EpochRecord&)> should_stop{};
  /// Once every setting, output and checkpoint has been checked (and a checkpoint resumed),
  /// before the first epoch: `epoch` is the number of epochs already done (0 for a new run).
  /// Work a program does for the run itself (an evaluation to print) belongs here, so that a
  /// refusal comes before it. The log is open by then (a new run's holds its header).
  std::function<void(long epoch)> on_start{};
};

/// How a run ended.
enum class RunEnd { Finished, EarlyStop, NonFinite, Requested, OutputFailed };

/// What a run did.
template <class Scalar>
struct RunResult {
  RunEnd end = RunEnd::Finished;
  long resumed_from = 0;              ///< the checkpoint's epoch; 0 for a fresh start
  long epochs = 0;                    ///< last completed epoch
  std::optional<EpochRecord> last;    ///< its record
  long best_epoch = 0;                ///< 0 when nothing was evaluated
  double best_loss = 0;
  Vector<Scalar> best_params;         ///< empty when nothing was evaluated
  long skipped_batches = 0;           ///< of the completed epochs (not of an undone one)
  std::optional<NonFiniteEvent> stop_event;  ///< the event that stopped the run (NonFinite)
  std::string output_error;           ///< what failed to be written (OutputFailed)
  std::string saved_params;           ///< path the final parameters were saved to, if any
};

}  // namespace sbptt
