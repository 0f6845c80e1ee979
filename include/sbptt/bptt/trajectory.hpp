#pragma once
/// \file What one forward pass stores for the reverse sweep.
#include <vector>

#include "sbptt/core/types.hpp"

namespace sbptt {

/// A stored batch rollout: states x_0..x_m (each state_dim × B), controls c_0..c_{m-1}
/// (each control_dim × B), and the controller's workspace of every step.
///
/// Memory: (m+1)·state_dim·B + m·control_dim·B scalars plus m controller workspaces (for an
/// MLP, the activations: m·B·Σ widths). Buffers are kept between passes and only resized
/// when the batch shape changes, so a training loop allocates once.
template <class Scalar, class Workspace>
struct Trajectory {
  std::vector<Matrix<Scalar>> states;
  std::vector<Matrix<Scalar>> controls;
  std::vector<Workspace> workspaces;

  [[nodiscard]] Index steps() const { return static_cast<Index>(controls.size()); }
  [[nodiscard]] Index batch() const { return states.empty() ? 0 : states.front().cols(); }

  /// Sizes the buffers for `steps` steps of a batch of `batch` samples.
  void resize(Index steps, Index state_dim, Index control_dim, Index batch) {
    const auto m = static_cast<std::size_t>(steps);
    states.resize(m + 1);
    controls.resize(m);
    workspaces.resize(m);
    for (auto& x : states) x.resize(state_dim, batch);
    for (auto& c : controls) c.resize(control_dim, batch);
  }
};

}  // namespace sbptt
