#pragma once
// The cart pole's state in the two layouts: CartPole orders it per pole (x, ẋ, θ_1, θ̇_1, …),
// MuJoCo by kind (qpos = x, θ_1, …; qvel = ẋ, θ̇_1, …). For the comparisons of
// tests/test_sim_mujoco.cpp and examples/bench_mujoco.cpp.
#include <sbptt/core/types.hpp>

namespace sbptt::examples {

/// The MuJoCo state (2 + 2P) of a CartPole state (2 + 2P).
inline Vector<double> to_mujoco_layout(const Vector<double>& cart, Index poles) {
  Vector<double> mj(cart.size());
  mj(0) = cart(0);
  mj(poles + 1) = cart(1);
  for (Index i = 0; i < poles; ++i) {
    mj(1 + i) = cart(2 + 2 * i);
    mj(poles + 2 + i) = cart(3 + 2 * i);
  }
  return mj;
}

/// The permutation Π of `to_mujoco_layout` (mj = Π cart), (2 + 2P) × (2 + 2P); Jacobians
/// map as A_mj = Π A Πᵀ, B_mj = Π B.
inline Matrix<double> mujoco_layout_permutation(Index poles) {
  const Index n = 2 + 2 * poles;
  Matrix<double> pi(n, n);
  for (Index j = 0; j < n; ++j) pi.col(j) = to_mujoco_layout(Vector<double>::Unit(n, j), poles);
  return pi;
}

}  // namespace sbptt::examples
