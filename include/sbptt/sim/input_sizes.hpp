#pragma once
/// \file The size checks of a simulator with dynamic sizes: its inputs x and u, and the adjoint
/// λ of its `vjp`, against `state_dim()` and `control_dim()`. Fixed sizes are checked by their
/// types, so for them the checks compile to nothing. Used by `AutoDiffSimulator`, `Integrated`
/// and `LinearSystem`.
#include "sbptt/core/error.hpp"
#include "sbptt/core/types.hpp"

namespace sbptt::detail {

/// Requires dynamic-size inputs to match the simulator's sizes (fixed sizes are checked by
/// their types).
template <class Sim>
void check_input_sizes(const Sim& sim, const typename Sim::State& x,
                       const typename Sim::Control& u, const char* who) {
  if constexpr (Sim::State::RowsAtCompileTime == Eigen::Dynamic ||
                Sim::Control::RowsAtCompileTime == Eigen::Dynamic) {
    require(x.size() == sim.state_dim() && u.size() == sim.control_dim(), who, ": x has size ",
            x.size(), " and u size ", u.size(), "; expected state_dim() = ", sim.state_dim(),
            " and control_dim() = ", sim.control_dim());
  }
}

/// `check_input_sizes`, and an adjoint λ of the state's size.
template <class Sim>
void check_vjp_sizes(const Sim& sim, const typename Sim::State& x, const typename Sim::Control& u,
                     const typename Sim::State& lambda, const char* who) {
  check_input_sizes(sim, x, u, who);
  if constexpr (Sim::State::RowsAtCompileTime == Eigen::Dynamic) {
    require(lambda.size() == sim.state_dim(), who, ": lambda has size ", lambda.size(),
            "; expected state_dim() = ", sim.state_dim());
  }
}

}  // namespace sbptt::detail
