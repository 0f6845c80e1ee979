#pragma once
/// \file The paper's guidance task (§4) on `GuidanceByRepulsion` (guidance_by_repulsion.hpp,
/// equations and state layout there): the loss of the evaders' distance to the origin and the
/// distribution of the initial states.
///
/// State layout: drivers first, then evaders; per agent p_x, p_y, v_x, v_y (size 4(D + E)).
///
///     ℓ(x) = Σ_e ‖p_e‖² / (2E)
#include <cmath>
#include <numbers>

#include <Eigen/Core>

#include "sbptt/core/error.hpp"
#include "sbptt/core/rng.hpp"
#include "sbptt/core/types.hpp"
#include "sbptt/sim/guidance_by_repulsion.hpp"

namespace sbptt {

/// Physics loss ℓ(x) = Σ_e ‖p_e‖² / (2E): the mean over evaders and coordinates of p², i.e.
/// ‖p_e‖²/2 averaged over evaders (target at the origin, as hard-coded in the reference).
template <class ScalarT = double, int Drivers = 2, int Evaders = 4>
class GuidanceLoss {
public:
  using Scalar = ScalarT;
  using State = typename GuidanceByRepulsion<Scalar, Drivers, Evaders>::State;

  GuidanceLoss()
    requires(Drivers != Eigen::Dynamic && Evaders != Eigen::Dynamic)
      : drivers_(Drivers), evaders_(Evaders) {}

  /// Agent counts at run time; throws InvalidArgument unless both are ≥ 1.
  GuidanceLoss(Index drivers, Index evaders) : drivers_(drivers), evaders_(evaders) {
    detail::require(drivers >= 1 && evaders >= 1, "GuidanceLoss: drivers = ", drivers,
                    ", evaders = ", evaders, ", expected both >= 1");
  }

  /// Throws `InvalidArgument` unless the loss's agents fill `state_dim` numbers; the engine
  /// calls it when it is built (with run-time agent counts the loss may have other counts).
  /// Only the total can be told from `state_dim`: counts swapped (3 drivers and 2 evaders
  /// against 2 and 3) pass.
  void check_state_dim(Index state_dim) const {
    detail::require(state_size() == state_dim, "GuidanceLoss: ", drivers_, " drivers and ",
                    evaders_, " evaders make states of ", state_size(),
                    " numbers; expected the simulator's state_dim = ", state_dim);
  }

  /// Returns ℓ(x) (x: 4(D+E)); if `grad` is not null sets *grad = ∂ℓ/∂x (p_e / E on evader
  /// positions, 0 elsewhere). Throws InvalidArgument on a wrong state size.
  Scalar operator()(const State& x, State* grad) const {
    const Index n = state_size();
    detail::require(x.size() == n, "GuidanceLoss: state size ", x.size(), ", expected ", n);
    const Scalar inv_e = Scalar(1) / static_cast<Scalar>(evaders_);
    if (grad != nullptr) grad->setZero(n);
    Scalar sum(0);
    for (Index e = drivers_; e < drivers_ + evaders_; ++e) {
      const auto p = x.template segment<2>(4 * e);
      sum += p.squaredNorm();
      if (grad != nullptr) grad->template segment<2>(4 * e) = inv_e * p;
    }
    return Scalar(0.5) * inv_e * sum;
  }

private:
  [[nodiscard]] Index state_size() const { return 4 * (drivers_ + evaders_); }

  Index drivers_, evaders_;
};

/// Draws `count` initial states of the paper's distribution (state_dim × count, one sample per
/// column; all velocities 0). Per sample, in this order: each driver radius ~ U[3, 4) (uniform
/// in r, not in area) then angle ~ U[0, 2π); the evader group centre radius ~ U[1, 2) then
/// angle; then each evader's offset (x, y) ~ U[−0.5, 0.5)².
template <class Scalar, int Drivers, int Evaders>
[[nodiscard]] Matrix<Scalar> guidance_initial_states(
    const GuidanceByRepulsion<Scalar, Drivers, Evaders>& sim, Rng& rng, Index count) {
  detail::require(count >= 0, "guidance_initial_states: count = ", count, ", expected >= 0");
  constexpr double two_pi = 2.0 * std::numbers::pi;
  Matrix<Scalar> states = Matrix<Scalar>::Zero(sim.state_dim(), count);
  const auto polar = [&](double r_low, double r_high, double& px, double& py) {
    const double radius = rng.uniform(r_low, r_high);
    const double angle = rng.uniform(0.0, two_pi);
    px = radius * std::cos(angle);
    py = radius * std::sin(angle);
  };
  for (Index j = 0; j < count; ++j) {
    double px = 0, py = 0;
    for (Index d = 0; d < sim.drivers(); ++d) {
      polar(3.0, 4.0, px, py);
      states(4 * d, j) = static_cast<Scalar>(px);
      states(4 * d + 1, j) = static_cast<Scalar>(py);
    }
    double cx = 0, cy = 0;
    polar(1.0, 2.0, cx, cy);
    for (Index e = sim.drivers(); e < sim.agents(); ++e) {
      states(4 * e, j) = static_cast<Scalar>(cx + rng.uniform(-0.5, 0.5));
      states(4 * e + 1, j) = static_cast<Scalar>(cy + rng.uniform(-0.5, 0.5));
    }
  }
  return states;
}

}  // namespace sbptt
