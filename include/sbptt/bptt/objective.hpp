#pragma once
/// \file What a rollout is scored by.
///
/// For one sample, with m steps, states x_0..x_m and controls c_0..c_{m-1}:
///
///     L = Σ_{n ∈ S} w · ℓ(x_n)  +  ρ / (m · k) · Σ_{n=0}^{m-1} ‖c_n‖²
///
/// where S = {m} for a final-state loss and S = {1, …, m} for a continuous one (x_0 is fixed
/// data and never scored), w is `step_weight` (1 for a sum over time, 1/m for a time mean),
/// ρ is `control_weight` and k = control_dim, so the regulariser is ρ times the mean squared
/// control. The batch loss is the mean of L over samples.
#include <concepts>

#include "sbptt/core/concepts.hpp"  // StateLoss
#include "sbptt/core/types.hpp"

namespace sbptt {

/// Which states the state loss scores.
enum class LossTiming {
  Final,       ///< ℓ(x_m) only
  Continuous,  ///< ℓ(x_n) for n = 1..m
};

/// A state loss with its timing and weights (see the file comment for the formula).
template <class Loss>
struct Objective {
  Loss state_loss{};
  LossTiming timing = LossTiming::Final;
  double step_weight = 1.0;     ///< w: multiplies every scored ℓ(x_n)
  double control_weight = 0.0;  ///< ρ: the control regulariser is ρ · mean_{n,k} c_{n,k}²
};

}  // namespace sbptt
