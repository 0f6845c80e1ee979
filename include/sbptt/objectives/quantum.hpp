#pragma once
/// \file The paper's quantum-control objective (docs/paper.md): the infidelity to the target state,
/// summed over time.
///
/// The objectives sit above the simulators and the engine (docs/design.md, "Layers"): a
/// simulator header knows its physics and its state losses, never the engine's `Objective`.
#include "sbptt/bptt/objective.hpp"
#include "sbptt/sim/schrodinger.hpp"

namespace sbptt {

/// The paper's objective: L = Σ_{n=1..m} (1 − |⟨φ_target, ψ_n⟩|²), summed over time
/// (Continuous timing, step weight 1, no control regulariser); the batch mean is the engine's.
template <class Scalar, int Nx>
[[nodiscard]] Objective<QuantumInfidelityLoss<Scalar, Nx>> quantum_objective(
    const Schrodinger1D<Scalar, Nx>& sim, Index target) {
  return {QuantumInfidelityLoss<Scalar, Nx>(sim, target), LossTiming::Continuous, 1.0, 0.0};
}

/// Same for a fixed grid size, e.g. `quantum_objective(5)` for the paper's hardest target.
template <class Scalar = double, int Nx = 32>
  requires(Nx != Eigen::Dynamic)
[[nodiscard]] Objective<QuantumInfidelityLoss<Scalar, Nx>> quantum_objective(Index target) {
  return quantum_objective(Schrodinger1D<Scalar, Nx>(), target);
}

}  // namespace sbptt
