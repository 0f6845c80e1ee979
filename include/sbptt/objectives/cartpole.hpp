#pragma once
/// \file The paper's cart-pole objective (docs/paper.md): the upright loss of the final state.
///
/// The objectives sit above the simulators and the engine (docs/design.md, "Layers"): a
/// simulator header knows its physics and its state losses, never the engine's `Objective`.
#include "sbptt/bptt/objective.hpp"
#include "sbptt/sim/cartpole.hpp"

namespace sbptt {

/// The paper's cart-pole objective: `CartPoleUprightLoss` on the final state only, no control
/// regulariser.
template <class Scalar = double, int Poles = 1>
[[nodiscard]] Objective<CartPoleUprightLoss<Scalar, Poles>> cartpole_objective() {
  Objective<CartPoleUprightLoss<Scalar, Poles>> objective;
  objective.timing = LossTiming::Final;
  objective.step_weight = 1.0;
  objective.control_weight = 0.0;
  return objective;
}

}  // namespace sbptt
