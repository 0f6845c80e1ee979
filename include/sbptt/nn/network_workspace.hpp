#pragma once
/// \file What a `Network` keeps between its calls, in buffers its caller owns: the record of a
/// forward pass (`Network::Workspace`), the layer adjoints of the first half of a backward pass
/// (`Network::LayerAdjoints`) and the packed weights (`Network::PackedWeights`). Only
/// `Network` reads or writes their contents (network.hpp); a caller creates them, keeps one per
/// concurrent pass, and passes them back. Their buffers are resized only when the batch or the
/// network changes, so that repeated calls at one shape allocate nothing. Each also says
/// whether it fits a given network, so that a call refuses another network's buffers before
/// any work.
#include <cstddef>
#include <variant>
#include <vector>

#include "sbptt/core/error.hpp"
#include "sbptt/core/types.hpp"
#include "sbptt/nn/layer.hpp"
#include "sbptt/nn/network_scratch.hpp"
#include "sbptt/nn/packed_product.hpp"

namespace sbptt {

template <class ScalarType>
class Network;

/// What `forward` records for `backward`. Default-constructible; one per concurrent forward
/// pass (the parts of one pass in `forward_columns` share one).
template <class Scalar>
class NetworkWorkspace {
public:
  /// B of the last forward pass or `size_forward` (−1 before the first).
  [[nodiscard]] Index batch_size() const { return batch_; }
  /// Output of layer `l` (after its activation), output_dim(l) × B.
  [[nodiscard]] const Matrix<Scalar>& layer_output(Index l) const {
    return outputs_.at(static_cast<std::size_t>(l));
  }
  /// Bytes of the recorded matrices: the input, every layer output and the im2col matrices.
  [[nodiscard]] std::size_t bytes() const {
    std::size_t entries = static_cast<std::size_t>(input_.size());
    for (const auto& m : outputs_) entries += static_cast<std::size_t>(m.size());
    for (const auto& m : columns_) entries += static_cast<std::size_t>(m.size());
    return entries * sizeof(Scalar);
  }

  /// Throws `InvalidArgument` unless `size_forward` of `network` sized this workspace: checked
  /// before a part of `forward_columns` could write past one of its buffers.
  template <class Net>
  void require_sized_for(const Net& network) const {
    detail::require(batch_ >= 0, "Network::forward_columns: the workspace holds no batch; ",
                    "expected size_forward(B, ws) first");
    const std::vector<Layer>& layers = network.layers();
    bool sized = outputs_.size() == layers.size() && input_.rows() == network.input_dim() &&
                 input_.cols() == batch_;
    for (std::size_t l = 0; sized && l < layers.size(); ++l) {
      sized = outputs_[l].rows() == layer_output_dim(layers[l]) && outputs_[l].cols() == batch_;
      if (const auto* conv = std::get_if<Conv1d>(&layers[l]))
        sized = sized && columns_[l].rows() == conv->window_size() &&
                columns_[l].cols() == conv->output_length() * batch_;
    }
    detail::require(sized, "Network::forward_columns: the workspace was sized for another ",
                    "network; expected size_forward(B, ws) of this one");
  }

  /// Throws `InvalidArgument` unless a forward pass of `network` filled this workspace.
  template <class Net>
  void require_filled_by(const Net& network) const {
    detail::require(batch_ >= 0, "Network::backward: the workspace holds no forward pass");
    const std::vector<Layer>& layers = network.layers();
    bool matches = outputs_.size() == layers.size() && input_.rows() == network.input_dim();
    for (std::size_t l = 0; matches && l < layers.size(); ++l)
      matches = outputs_[l].rows() == layer_output_dim(layers[l]);
    if (!matches)  // describe() only on failure: backward must not build strings per call
      throw InvalidArgument(detail::concat("Network::backward: the workspace was filled by a "
                                           "different network (layer sizes differ from ",
                                           network.describe(), ")"));
  }

private:
  template <class>
  friend class Network;
  Matrix<Scalar> input_;                // X, input_dim × B
  std::vector<Matrix<Scalar>> outputs_;  // per layer, output_dim × B
  std::vector<Matrix<Scalar>> columns_;  // per conv layer the im2col matrix, else empty
  Index batch_ = -1;
};

/// The pre-activation adjoints Δ_l of every layer at one batch, as `backward_inputs` records
/// them for `add_param_gradient`, and that pass's other temporaries. Default-constructible;
/// buffers only grow. The temporaries live here rather than in the thread's scratch, so that a
/// caller whose calls move between threads (the engine's pair of sweeps, claimed by whichever
/// thread is free) allocates nothing after its first call.
template <class Scalar>
class NetworkLayerAdjoints {
public:
  /// Throws `InvalidArgument` unless these adjoints cover a batch of `batch` samples of a
  /// network of `layers`.
  void require_recorded_for(const std::vector<Layer>& layers, Index batch) const {
    const auto& deltas = record_.deltas;
    bool recorded = deltas.size() >= layers.size();
    for (std::size_t l = 0; recorded && l < layers.size(); ++l)
      recorded = deltas[l].size() >= layer_output_dim(layers[l]) * batch;
    detail::require(recorded, "Network::add_param_gradient: the adjoints do not cover this ",
                    "workspace's batch; expected them recorded by backward_inputs at it");
  }

private:
  template <class>
  friend class Network;
  detail::NetworkScratch<Scalar> record_;  ///< deltas: the Δ_l
};

/// The layers' products packed from θ by `Network::pack`: valid while θ is unchanged.
template <class Scalar>
class NetworkPackedWeights {
public:
  /// Throws `InvalidArgument` unless these are W (or, when `transposed`, Wᵀ) of every layer of
  /// a network of `layers`: checked before a product could read or write past a buffer.
  /// Weights packed from another network of the same shapes cannot be told apart: that is
  /// the caller's contract. `caller` names the `Network` call in the message.
  void require_fit(const std::vector<Layer>& layers, bool transposed, const char* caller) const {
    bool matches = layers_.count == layers.size();
    for (std::size_t l = 0; matches && l < layers.size(); ++l) {
      const Index rows = layer_weight_rows(layers[l]);
      const Index cols = layer_weight_count(layers[l]) / rows;
      const PackedMatrix<Scalar>& m = transposed ? layers_.transposed[l] : layers_.weights[l];
      matches = transposed ? m.rows() == cols && m.cols() == rows
                           : m.rows() == rows && m.cols() == cols;
    }
    detail::require(matches, "Network::", caller, ": the packed weights do not fit this ",
                    "network's layers; expected weights packed by pack() of this network");
  }

private:
  template <class>
  friend class Network;
  detail::PackedLayers<Scalar> layers_;
};

}  // namespace sbptt
