#pragma once
/// \file The sizes of what a simulator writes, checked wherever the library calls it. A
/// simulator with run-time sizes that writes another size than its state_dim() or
/// control_dim() would otherwise be copied in part or read past its end: Eigen checks sizes
/// only in builds without NDEBUG. Fixed-size types make each check a constant.
#include "sbptt/core/error.hpp"
#include "sbptt/core/types.hpp"

namespace sbptt::detail {

/// Throws `InvalidArgument` unless the simulator's `product` ("step wrote x_next") has `size`
/// entries, `expected_name` (e.g. "state_dim()") being `expected`.
inline void require_output_size(const char* product, Index size, const char* expected_name,
                                Index expected) {
  require(size == expected, "the simulator's ", product, " of size ", size, "; expected ",
          expected_name, " = ", expected);
}

/// `sim.step`'s x_next has `state_dim` entries.
template <class State>
void check_step_output(const State& x_next, Index state_dim) {
  require_output_size("step wrote x_next", x_next.size(), "state_dim()", state_dim);
}

/// `sim.vjp`'s λ_x (if asked for) has `state_dim` entries and λ_u (if asked for) `control_dim`.
template <class State, class Control>
void check_vjp_output(const State* lambda_x, const Control* lambda_u, Index state_dim,
                      Index control_dim) {
  if (lambda_x != nullptr)
    require_output_size("vjp wrote lambda_x (Aᵀλ)", lambda_x->size(), "state_dim()", state_dim);
  if (lambda_u != nullptr)
    require_output_size("vjp wrote lambda_u (Bᵀλ)", lambda_u->size(), "control_dim()",
                        control_dim);
}

/// The matrix `product` that the simulator's `call` wrote ("step_batch", "x_next"; "jacobians",
/// "A") is `rows` × `cols`, the sizes `expected_name` (e.g. "state_dim() × B") names.
template <class Product>
void check_output_shape(const char* call, const char* product, const Product& written,
                        const char* expected_name, Index rows, Index cols) {
  require(written.rows() == rows && written.cols() == cols, "the simulator's ", call, " wrote ",
          product, " of ", written.rows(), " × ", written.cols(), "; expected ", expected_name,
          " = ", rows, " × ", cols);
}

/// `sim.jacobians`' A is `state_dim` × `state_dim` and B `state_dim` × `control_dim`.
template <class StateJacobian, class ControlJacobian>
void check_jacobians_output(const StateJacobian& a, const ControlJacobian& b, Index state_dim,
                            Index control_dim) {
  check_output_shape("jacobians", "A", a, "state_dim() × state_dim()", state_dim, state_dim);
  check_output_shape("jacobians", "B", b, "state_dim() × control_dim()", state_dim,
                     control_dim);
}

}  // namespace sbptt::detail
