#pragma once
/// \file The paper's guidance objective (docs/paper.md): the evaders' mean squared distance over time
/// plus rc times the mean squared control.
///
/// The objectives sit above the simulators and the engine (docs/design.md, "Layers"): a
/// simulator header knows its physics and its state losses, never the engine's `Objective`.
#include <cmath>

#include "sbptt/core/error.hpp"
#include "sbptt/bptt/objective.hpp"
#include "sbptt/sim/guidance_task.hpp"

namespace sbptt {

/// The paper's guidance objective for a simulator: `GuidanceLoss` at every step n = 1..Nt
/// weighted 1/Nt (a time mean), plus rc · mean_{n,d,k} c_{n,d,k}². Throws unless rc is finite
/// and ≥ 0.
template <class Scalar, int Drivers, int Evaders>
[[nodiscard]] Objective<GuidanceLoss<Scalar, Drivers, Evaders>> guidance_objective(
    const GuidanceByRepulsion<Scalar, Drivers, Evaders>& sim, double rc) {
  detail::require(std::isfinite(rc) && rc >= 0, "guidance_objective: rc = ", rc,
                  ", expected a finite value >= 0");
  Objective<GuidanceLoss<Scalar, Drivers, Evaders>> objective{
      GuidanceLoss<Scalar, Drivers, Evaders>(sim.drivers(), sim.evaders())};
  objective.timing = LossTiming::Continuous;
  objective.step_weight = 1.0 / static_cast<double>(sim.steps());
  objective.control_weight = rc;
  return objective;
}

/// Same for fixed agent counts without a simulator at hand: `steps` is the rollout length m.
template <class Scalar = double, int Drivers = 2, int Evaders = 4>
  requires(Drivers != Eigen::Dynamic && Evaders != Eigen::Dynamic)
[[nodiscard]] Objective<GuidanceLoss<Scalar, Drivers, Evaders>> guidance_objective(
    double rc, Index steps = 60) {
  detail::require(steps >= 1, "guidance_objective: steps = ", steps, ", expected >= 1");
  GuidanceOptions options;
  options.steps = steps;
  return guidance_objective(GuidanceByRepulsion<Scalar, Drivers, Evaders>(options), rc);
}

}  // namespace sbptt
