#pragma once
/// \file The argument checks every optimizer makes, in the same words (Adam, Sgd): a finite
/// positive learning rate, a decay rate in [0, 1), and parameter and gradient vectors of one
/// size.
#include <cmath>
#include <concepts>

#include "sbptt/core/error.hpp"
#include "sbptt/core/types.hpp"

namespace sbptt {

namespace detail {

template <std::floating_point Scalar>
void require_learning_rate(Scalar learning_rate, const char* who) {
  require(std::isfinite(learning_rate) && learning_rate > Scalar(0), who, ": learning rate = ",
          learning_rate, "; expected a finite number > 0");
}

/// β must leave some weight on the new value (β < 1) and be a decay (β ≥ 0).
template <std::floating_point Scalar>
void require_decay(Scalar beta, const char* who, const char* name) {
  require(beta >= Scalar(0) && beta < Scalar(1), who, ": ", name, " = ", beta,
          "; expected a number in [0, 1)");
}

/// The step's two vectors must match each other and, once state exists, the state.
template <std::floating_point Scalar>
void require_step_sizes(const Vector<Scalar>& params, const Vector<Scalar>& grad,
                        Index state_size, bool has_state, const char* who) {
  require(grad.size() == params.size(), who, ": gradient size = ", grad.size(),
          ", expected the parameter size ", params.size());
  require(!has_state || params.size() == state_size, who, ": parameter size = ", params.size(),
          ", expected ", state_size,
          " (the size the optimizer state was created with; call reset() to start over)");
}

}  // namespace detail

}  // namespace sbptt
