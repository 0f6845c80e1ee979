#pragma once
/// \file Generic state losses (task losses live beside their simulators).
#include "sbptt/core/error.hpp"
#include "sbptt/core/non_finite.hpp"
#include "sbptt/core/types.hpp"

namespace sbptt {

/// ℓ(x) = ½ ‖x − y‖², the squared distance to a target state y.
template <class State>
struct SquaredDistanceLoss {
  State target;

  /// Throws `InvalidArgument` unless the target has `state_dim` entries, all finite; the
  /// engine calls it when it is built (a dynamic-size target can have any size, and a NaN in it
  /// would only show as a non-finite loss in the first batch).
  void check_state_dim(Index state_dim) const {
    detail::require(target.size() == state_dim, "SquaredDistanceLoss: the target has ",
                    target.size(), " entries; expected the simulator's state_dim = ", state_dim);
    if (const auto bad = first_non_finite(target))
      throw InvalidArgument(detail::concat("SquaredDistanceLoss: the target's entry ", bad->row,
                                           " is ", detail::value_text(target(bad->row)),
                                           "; expected finite numbers"));
  }

  typename State::Scalar operator()(const State& x, State* grad) const {
    if (grad) *grad = x - target;
    return typename State::Scalar(0.5) * (x - target).squaredNorm();
  }
};

}  // namespace sbptt
