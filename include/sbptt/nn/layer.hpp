#pragma once
/// \file One layer of a `Network` (a dense or a 1-D convolution layer, dense.hpp and
/// conv1d.hpp) and the questions the network asks of any of them.
#include <string>
#include <variant>

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

}  // namespace sbptt
