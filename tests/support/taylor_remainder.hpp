#pragma once
// The Taylor remainder of a simulator's step against its own Jacobians, shared by the tests
// that check A and B without finite differences: it falls 4-fold when h halves (O(h²)).
#include "sbptt/core/types.hpp"

namespace sbptt::testing {

/// ‖P(x+hδ, u+hη) − P(x,u) − h(Aδ + Bη)‖ for one h.
template <class Sim>
double taylor_remainder(const Sim& sim, const typename Sim::State& x,
                        const typename Sim::Control& u, const typename Sim::State& dx,
                        const typename Sim::Control& du, double h) {
  typename Sim::StateJacobian a;
  typename Sim::ControlJacobian b;
  sim.jacobians(x, u, a, b);
  typename Sim::State base, moved;
  sim.step(x, u, base);
  const typename Sim::State xh = x + h * dx;
  const typename Sim::Control uh = u + h * du;
  sim.step(xh, uh, moved);
  return (moved - base - h * (a * dx + b * du)).norm();
}

}  // namespace sbptt::testing
