#pragma once
/// \file Generic state losses (task losses live beside their simulators).
#include "sbptt/core/types.hpp"

namespace sbptt {

/// ℓ(x) = ½ ‖x − y‖², the squared distance to a target state y.
template <class State>
struct SquaredDistanceLoss {
  State target;

  typename State::Scalar operator()(const State& x, State* grad) const {
    if (grad) *grad = x - target;
    return typename State::Scalar(0.5) * (x - target).squaredNorm();
  }
};

}  // namespace sbptt
