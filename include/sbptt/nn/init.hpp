#pragma once
/// \file Glorot-uniform initialisation (Keras defaults) from an explicit seeded generator.
///
/// Each weight is drawn from U(−a, a) with a = √(6 / (fan_in + fan_out)) (Glorot & Bengio
/// 2010, Keras `GlorotUniform`); biases are zero. Fans: dense (n_in, n_out); conv1d
/// (C_in·K, C_out·K), the Keras `Conv1D` convention. Draws go in flat-parameter order, layer by
/// layer, so a seed fixes every value on every platform (`Rng` is fully specified).
///
/// Paper note: the quantum controller's first layer is a Keras Conv2D with kernel (3, 2) over a
/// (32, 2, 1) input, which is the same function as our Conv1d with C_in = 2, K = 3, but Keras
/// counts its fan_out as 3·2·60 = 360 rather than 3·60 = 180. Pass `fan_overrides` to mimic
/// it exactly.
#include <cmath>
#include <optional>
#include <tuple>
#include <utility>
#include <vector>

#include "sbptt/core/error.hpp"
#include "sbptt/core/rng.hpp"
#include "sbptt/nn/network.hpp"

namespace sbptt {

/// Options of `glorot_uniform`.
struct GlorotOptions {
  /// Zero the LAST layer's weights (its bias is zero anyway), so the initial output is exactly
  /// the (zero) bias for every input. The paper's cart pole and guidance runs start this way.
  bool zero_last_kernel = false;
  /// Per layer, (fan_in, fan_out) to use instead of the layer's own; empty or `std::nullopt`
  /// entries keep the default. At most num_layers() entries.
  std::vector<std::optional<std::pair<Index, Index>>> fan_overrides = {};
};

/// a = √(6 / (fan_in + fan_out)), the half-width of the Glorot-uniform interval.
[[nodiscard]] inline double glorot_limit(Index fan_in, Index fan_out) {
  detail::require(fan_in > 0 && fan_out > 0, "glorot_limit: fan_in = ", fan_in,
                  ", fan_out = ", fan_out, ", expected both > 0");
  return std::sqrt(6.0 / static_cast<double>(fan_in + fan_out));
}

/// (fan_in, fan_out) of a layer, Keras convention (see the file comment).
[[nodiscard]] inline std::pair<Index, Index> glorot_fans(const Layer& layer) {
  return std::visit([](const auto& l) { return std::pair<Index, Index>{l.fan_in(), l.fan_out()}; },
                    layer);
}

/// Overwrites every parameter of `net`: Glorot-uniform weights drawn from `rng`, zero biases.
/// Layers are drawn in order; a zeroed last kernel consumes no draws.
template <class Scalar>
void glorot_uniform(Network<Scalar>& net, Rng& rng, const GlorotOptions& options = {}) {
  detail::require(static_cast<Index>(options.fan_overrides.size()) <= net.num_layers(),
                  "glorot_uniform: ", options.fan_overrides.size(),
                  " fan overrides, expected at most num_layers() = ", net.num_layers());
  Vector<Scalar>& theta = net.params();
  theta.setZero(net.num_params());
  for (Index l = 0; l < net.num_layers(); ++l) {
    const auto ul = static_cast<std::size_t>(l);
    if (options.zero_last_kernel && l == net.num_layers() - 1) break;
    auto [fan_in, fan_out] = glorot_fans(net.layers()[ul]);
    if (ul < options.fan_overrides.size() && options.fan_overrides[ul])
      std::tie(fan_in, fan_out) = *options.fan_overrides[ul];
    const double limit = glorot_limit(fan_in, fan_out);
    const Index begin = net.param_offset(l);
    const Index end = begin + layer_weight_count(net.layers()[ul]);
    for (Index i = begin; i < end; ++i) theta(i) = static_cast<Scalar>(rng.uniform(-limit, limit));
  }
}

}  // namespace sbptt
