#pragma once
/// \file One layer of a `Network` (a dense or a 1-D convolution layer, dense.hpp and
/// conv1d.hpp) and the questions the network asks of any of them.
#include <cstddef>
#include <string>
#include <variant>

#include "sbptt/core/error.hpp"
#include "sbptt/core/types.hpp"
#include "sbptt/nn/activation.hpp"
#include "sbptt/nn/conv1d.hpp"
#include "sbptt/nn/dense.hpp"

namespace sbptt {

/// One layer of a `Network`.
using Layer = std::variant<Dense, Conv1d>;

/// Size of the layer's input column (one sample).
[[nodiscard]] inline Index layer_input_dim(const Layer& layer) {
  return std::visit([](const auto& l) { return l.input_dim(); }, layer);
}
/// Size of the layer's output column (one sample).
[[nodiscard]] inline Index layer_output_dim(const Layer& layer) {
  return std::visit([](const auto& l) { return l.output_dim(); }, layer);
}
/// Number of entries of the layer's slice of the flat parameter vector.
[[nodiscard]] inline Index layer_num_params(const Layer& layer) {
  return std::visit([](const auto& l) { return l.num_params(); }, layer);
}
/// Rows of the layer's weight read as a matrix; its columns are layer_weight_count / this.
[[nodiscard]] inline Index layer_weight_rows(const Layer& layer) {
  return std::visit([](const auto& l) { return l.weight_rows(); }, layer);
}
/// Number of weight (kernel) entries; the bias follows them in the layer's slice.
[[nodiscard]] inline Index layer_weight_count(const Layer& layer) {
  return std::visit([](const auto& l) { return l.weight_count(); }, layer);
}
[[nodiscard]] inline Activation layer_activation(const Layer& layer) {
  return std::visit([](const auto& l) { return l.activation; }, layer);
}
[[nodiscard]] inline std::string layer_describe(const Layer& layer) {
  return std::visit([](const auto& l) { return l.describe(); }, layer);
}

namespace detail {

/// Throws `InvalidArgument` unless layer `l` (`current`) takes what layer l − 1 (`previous`)
/// produces; conv → conv must also agree in positions and channels.
inline void check_layers_chain(const Layer& previous, const Layer& current, std::size_t l) {
  require(layer_output_dim(previous) == layer_input_dim(current), "Network: layer ", l, " (",
          layer_describe(current), ") expects ", layer_input_dim(current), " inputs, but layer ",
          l - 1, " (", layer_describe(previous), ") produces ", layer_output_dim(previous));
  // Equal totals with a different positions × channels split would silently reinterpret the
  // memory; that is never what a conv stack means.
  const auto* a = std::get_if<Conv1d>(&previous);
  const auto* b = std::get_if<Conv1d>(&current);
  if (a != nullptr && b != nullptr) {
    require(a->output_length() == b->length && a->out_channels == b->in_channels,
            "Network: layer ", l, " (", b->describe(), ") expects ", b->length,
            " positions × ", b->in_channels, " channels, but layer ", l - 1, " (",
            a->describe(), ") produces ", a->output_length(), " × ", a->out_channels);
  }
}

}  // namespace detail

}  // namespace sbptt
