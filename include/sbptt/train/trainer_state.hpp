#pragma once
/// \file A trainer's state between epochs (parameters, optimizer, shuffling state, epoch),
/// kept by `run_training` to checkpoint an epoch after the next one has begun, and to undo an
/// epoch trained ahead (evaluate_beside).
#include <string>
#include <type_traits>

#include "sbptt/core/types.hpp"

namespace sbptt::detail {

/// What `run_training` keeps of a trainer between epochs, to checkpoint or restore it.
template <class Scalar, class Optimizer>
struct TrainerState {
  Vector<Scalar> params;
  Optimizer optimizer;
  std::string shuffle_state;
  long epoch = 0;
};

template <class TrainerT>
[[nodiscard]] auto state_of(TrainerT& trainer) {
  using Optimizer = std::remove_cvref_t<decltype(trainer.optimizer())>;
  return TrainerState<typename TrainerT::Scalar, Optimizer>{
      trainer.controller().params(), trainer.optimizer(), trainer.shuffle_state(),
      trainer.epoch()};
}

/// The parameters and the optimizer of `state` back in `trainer`.
template <class TrainerT, class State>
void restore_parameters_and_optimizer(TrainerT& trainer, const State& state) {
  trainer.controller().params() = state.params;
  trainer.optimizer() = state.optimizer;
}

/// All of `state` back in `trainer`: the next epoch is `state.epoch` + 1.
template <class TrainerT, class State>
void restore_trainer(TrainerT& trainer, const State& state) {
  restore_parameters_and_optimizer(trainer, state);
  trainer.resume_at(state.epoch, state.shuffle_state);
}

}  // namespace sbptt::detail
