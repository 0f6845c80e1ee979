#pragma once
/// \file What one forward pass stores for the reverse sweep.
#include <cstddef>
#include <vector>

#include "sbptt/core/types.hpp"

namespace sbptt {

/// A stored batch rollout: states x_0..x_m (each state_dim × B), controls c_0..c_{m-1}
/// (each control_dim × B), and the controller's workspace of every step.
///
/// Memory: (m+1)·state_dim·B + m·control_dim·B scalars plus m controller workspaces (for an
/// MLP, the input and the activations: m·B·(input_dim + Σ widths); a convolution also keeps
/// its im2col matrix, C_in·K·P·B per layer). It grows linearly in the horizon m and in the
/// batch B, and linearly in the widths. `bytes()` counts it. Buffers are kept between passes
/// and only resized when the batch shape changes, so a training loop allocates once.
template <class Scalar, class Workspace>
struct Trajectory {
  std::vector<Matrix<Scalar>> states;
  std::vector<Matrix<Scalar>> controls;
  std::vector<Workspace> workspaces;

  [[nodiscard]] Index steps() const { return static_cast<Index>(controls.size()); }
  [[nodiscard]] Index batch() const { return states.empty() ? 0 : states.front().cols(); }

  /// Bytes held by the states, the controls and (when the workspace type reports it through a
  /// `bytes()` member, as `Network`'s does) the controller workspaces.
  [[nodiscard]] std::size_t bytes() const {
    std::size_t total = 0;
    for (const auto& x : states) total += static_cast<std::size_t>(x.size()) * sizeof(Scalar);
    for (const auto& c : controls) total += static_cast<std::size_t>(c.size()) * sizeof(Scalar);
    if constexpr (requires(const Workspace& ws) { ws.bytes(); }) {
      for (const auto& ws : workspaces) total += static_cast<std::size_t>(ws.bytes());
    }
    return total;
  }

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
