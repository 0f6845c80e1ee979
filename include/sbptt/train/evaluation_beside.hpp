#pragma once
/// \file An epoch's evaluation on a second thread, beside the next epoch's training.
///
/// The evaluation of the train and test sets after epoch e reads only the parameters θ_e, and
/// the training of epoch e+1 reads nothing the evaluation writes. So the two can run at once,
/// each on a core of its own, the evaluation on a copy of θ_e: an epoch then takes about as
/// long as its training batches alone. Threads inside a batch meet at every step; these two
/// meet once an epoch, which pays on hosts where a cache line is slow to cross from core to
/// core (docs/training.md, "The evaluation beside the next epoch").
///
/// The evaluation runs on an engine of its own with one thread, over a copy of the controller:
/// it gives bitwise the losses and the non-finite events of `Trainer::train_epoch`'s own
/// evaluation, because an engine's results do not depend on its number of threads. The copy
/// must own its parameters (checked) and share no mutable state with the original; the
/// simulator and the loss serve both threads at once, as with `TrainerOptions::threads`.
#include <concepts>
#include <type_traits>
#include <utility>
#include <vector>

#include "sbptt/core/parallel.hpp"
#include "sbptt/train/trainer.hpp"

namespace sbptt {

namespace detail {

/// The pool of the evaluation beside the training: its one thread beside the caller. Its
/// failure names it, as the message would otherwise count 2 threads a user never asked for.
inline ThreadPool evaluation_thread_pool() {
  try {
    return ThreadPool(2);
  } catch (const ResourceError& e) {
    throw ResourceError(concat("evaluate_beside: its thread beside the training: ", e.what()));
  }
}

}  // namespace detail

/// The second thread, engine and controller copy of `run_training`'s `evaluate_beside`.
template <class TrainerT>
class EvaluationBeside {
public:
  using Scalar = typename TrainerT::Scalar;
  using Ctrl = std::remove_reference_t<decltype(std::declval<TrainerT&>().controller())>;
  using EngineT = std::remove_reference_t<decltype(std::declval<TrainerT&>().engine())>;
  explicit EvaluationBeside(TrainerT& trainer)
      : controller_(trainer.controller()),
        engine_(trainer.engine().simulator(), controller_, trainer.engine().objective(),
                trainer.engine().steps()),
        pool_(detail::evaluation_thread_pool()) {
    static_assert(std::copy_constructible<Ctrl>,
                  "the evaluation beside the training needs a copy of the controller");
    // A view of a network (one holding a reference to it) copies as a second view of it: the
    // evaluation would write the parameters the training reads.
    detail::require(&controller_.params() != &trainer.controller().params(),
                    "evaluate_beside: the copy of the controller shares its parameters with "
                    "the trained one (it is a view of them); expected a controller whose copy "
                    "owns its parameters");
  }

  // The engine refers to the controller copy inside this object.
  EvaluationBeside(const EvaluationBeside&) = delete;
  EvaluationBeside& operator=(const EvaluationBeside&) = delete;

  /// Evaluates the parameters `params` on `train` and `test` (no test set when empty) into
  /// `record`, appending each non-finite rollout to `events`, on the second thread while
  /// `foreground()` runs on the calling thread. Returns when both are done; rethrows the
  /// first exception, `foreground`'s before the evaluation's.
  template <class Foreground>
  void run(const Vector<Scalar>& params, const Matrix<Scalar>& train, const Matrix<Scalar>& test,
           EpochRecord& record, std::vector<NonFiniteEvent>& events, Foreground&& foreground) {
    controller_.params() = params;
    auto evaluation = [&](Index, Index) {
      detail::evaluate_sets(engine_, train, test, record,
                            [&](const NonFiniteEvent& event) { events.push_back(event); });
    };
    pool_.run_beside(1, evaluation, std::forward<Foreground>(foreground));
  }

private:
  Ctrl controller_;
  EngineT engine_;
  detail::ThreadPool pool_;
};

}  // namespace sbptt
