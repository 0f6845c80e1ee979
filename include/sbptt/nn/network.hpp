#pragma once
/// \file Sequential network of dense and 1-D convolution layers with one flat parameter
/// vector: the library's `Controller`.
///
/// Parameter order (docs/formats.md): layers from input to output, each layer's weight then its bias
/// (see dense.hpp and conv1d.hpp for the per-layer layouts). A conv output feeds a dense layer
/// with no reshape, because samples are stored position-major throughout.
///
/// Products: every layer multiplies by W (forward) and Wᵀ (input VJP) in the packed layout of
/// packed_product.hpp. `pack` packs them once for as long as θ stays unchanged (the engine does
/// it once per rollout); the overloads without packed weights pack on every call.
///
/// Memory: `forward` keeps what `backward` needs in the caller's `Workspace` (input copy,
/// every layer's output, the im2col matrices) and resizes those buffers only when the batch
/// size or the network changes. `backward` takes the workspace `const`, so its own temporaries
/// (layer adjoints) live in thread-local buffers (network_scratch.hpp) that only ever grow
/// (the split halves keep them in the caller's `LayerAdjoints` instead):
/// after the first call on a thread, repeated calls at the same sizes allocate nothing, and
/// several threads may run `backward` on the same workspace at once (e.g. the two sweeps of
/// the combined update).
#include <cstddef>
#include <initializer_list>
#include <string>
#include <type_traits>
#include <utility>
#include <variant>
#include <vector>

#include "sbptt/core/concepts.hpp"
#include "sbptt/core/error.hpp"
#include "sbptt/core/types.hpp"
#include "sbptt/core/unroll.hpp"
#include "sbptt/nn/activation.hpp"
#include "sbptt/nn/layer.hpp"
#include "sbptt/nn/network_scratch.hpp"
#include "sbptt/nn/network_workspace.hpp"
#include "sbptt/nn/outer_product.hpp"
#include "sbptt/nn/packed_product.hpp"

namespace sbptt {

/// A sequential stack of `Dense` / `Conv1d` layers; satisfies `sbptt::Controller`.
///
/// Parameters start at zero; use `glorot_uniform` (init.hpp) or `load_parameters`
/// (parameters_io.hpp) to set them.
template <class ScalarType = double>
class Network {
public:
  using Scalar = ScalarType;

  /// What `forward` records for `backward` (network_workspace.hpp).
  using Workspace = NetworkWorkspace<Scalar>;
  /// The layer adjoints that `backward_inputs` records for `add_param_gradient`.
  using LayerAdjoints = NetworkLayerAdjoints<Scalar>;
  /// The layers' products packed from θ by `pack`: valid while θ is unchanged.
  using PackedWeights = NetworkPackedWeights<Scalar>;

  /// A network of the given layers (input to output), parameters zero.
  /// Throws `InvalidArgument` if the list is empty, a layer is malformed, or consecutive sizes
  /// do not chain (conv → conv must also agree in positions and channels).
  explicit Network(std::vector<Layer> layers) : layers_(std::move(layers)) {
    detail::require(!layers_.empty(), "Network: no layers, expected at least one");
    Index offset = 0;
    for (std::size_t l = 0; l < layers_.size(); ++l) {
      std::visit([](const auto& layer) { layer.validate(); }, layers_[l]);
      if (l > 0) detail::check_layers_chain(layers_[l - 1], layers_[l], l);
      offsets_.push_back(offset);
      offset += layer_num_params(layers_[l]);
    }
    params_ = Vector<Scalar>::Zero(offset);
  }

  /// Same, from a braced list: `Network<>({Conv1d{...}, Dense{...}})`.
  Network(std::initializer_list<Layer> layers) : Network(std::vector<Layer>(layers)) {}

  /// Multi-layer perceptron inputs → hidden[0] → … → outputs; hidden layers use
  /// `hidden_activation`, the output layer is linear (Identity).
  [[nodiscard]] static Network mlp(Index inputs, const std::vector<Index>& hidden, Index outputs,
                                   Activation hidden_activation = Activation::Tanh) {
    std::vector<Layer> layers;
    Index previous = inputs;
    for (const Index width : hidden) {
      layers.emplace_back(Dense{previous, width, hidden_activation});
      previous = width;
    }
    layers.emplace_back(Dense{previous, outputs, Activation::Identity});
    return Network(std::move(layers));
  }

  [[nodiscard]] Index input_dim() const { return layer_input_dim(layers_.front()); }
  [[nodiscard]] Index output_dim() const { return layer_output_dim(layers_.back()); }
  [[nodiscard]] Index num_params() const {
    return offsets_.back() + layer_num_params(layers_.back());
  }
  [[nodiscard]] Index num_layers() const { return static_cast<Index>(layers_.size()); }
  [[nodiscard]] const std::vector<Layer>& layers() const { return layers_; }
  /// Index of layer `l`'s first parameter (its weight) in the flat vector.
  [[nodiscard]] Index param_offset(Index l) const {
    return offsets_.at(static_cast<std::size_t>(l));
  }

  /// The flat parameter vector θ, num_params() entries.
  [[nodiscard]] const Vector<Scalar>& params() const { return params_; }
  /// Writable θ; keep its size at num_params() (forward checks).
  [[nodiscard]] Vector<Scalar>& params() { return params_; }

  /// e.g. "dense 24→100 tanh | dense 100→4 identity (2904 parameters)".
  [[nodiscard]] std::string describe() const {
    std::string text;
    for (const auto& layer : layers_) text += (text.empty() ? "" : " | ") + layer_describe(layer);
    return text + detail::concat(" (", num_params(), " parameters)");
  }

  /// Packs W (with b) and Wᵀ of every layer from the current θ (see the file comment). Reuses
  /// the storage of `packed` when the network is the same.
  void pack(PackedWeights& packed) const {
    check_params_size();
    pack_layers(packed.layers_, true, true);
  }

  /// Y = N(X; θ).
  /// \param x   inputs, input_dim() × B, one sample per column
  /// \param y   outputs, resized to output_dim() × B; may be `x`
  /// \param ws  records what `backward` needs; reused buffers, resized only when B changes
  void forward(const Matrix<Scalar>& x, Matrix<Scalar>& y, Workspace& ws) const {
    check_params_size();
    auto& packed = detail::packed_scratch<Scalar>();
    pack_layers(packed, true, false);
    forward_packed(x, y, ws, packed);
  }

  /// The same with θ as packed by `pack` (which must have seen the current θ).
  void forward(const Matrix<Scalar>& x, Matrix<Scalar>& y, Workspace& ws,
               const PackedWeights& packed) const {
    check_packed(packed, false, "forward");
    forward_packed(x, y, ws, packed.layers_);
  }

  /// Sizes `ws` for a forward pass of `batch` samples done by `forward_columns` in parts.
  /// Allocates only when the batch or the network changed.
  void size_forward(Index batch, Workspace& ws) const {
    detail::require(batch >= 0, "Network::size_forward: batch = ", batch,
                    "; expected a number of samples >= 0");
    const std::size_t count = layers_.size();
    if (ws.outputs_.size() != count) {
      ws.outputs_.resize(count);
      ws.columns_.resize(count);
    }
    ws.input_.resize(input_dim(), batch);
    for (std::size_t l = 0; l < count; ++l) {
      ws.outputs_[l].resize(layer_output_dim(layers_[l]), batch);
      if (const auto* conv = std::get_if<Conv1d>(&layers_[l]))
        ws.columns_[l].resize(conv->window_size(), conv->output_length() * batch);
    }
    ws.batch_ = batch;
  }

  /// One part of the packed `forward`: samples `first` … `first` + X.cols() − 1 of the batch
  /// that `ws` was sized for by `size_forward`. Sets `y` (output_dim() × X.cols()) and those
  /// samples' columns of `ws`. A sample's outputs do not depend on the samples beside it
  /// (packed_product.hpp, `activate_in_place`), so the parts give the whole batch's numbers bit
  /// for bit, and calls on disjoint samples may run at once (the engine's forward pass on
  /// several threads). X and Y belong to the caller's part, so that parts on different
  /// threads share no memory but the workspace.
  void forward_columns(const Matrix<Scalar>& x, Index first, Matrix<Scalar>& y, Workspace& ws,
                       const PackedWeights& packed) const {
    ws.require_sized_for(*this);
    detail::require(first >= 0 && x.cols() > 0 && first + x.cols() <= ws.batch_,
                    "Network::forward_columns: samples ", first, " … ", first + x.cols() - 1,
                    "; expected a range within the ", ws.batch_,
                    " samples the workspace was sized for (size_forward)");
    check_input_rows(x, "forward_columns");
    check_packed(packed, false, "forward_columns");
    forward_range(x, first, y, ws, packed.layers_);
  }

  /// Vector–Jacobian products at the batch recorded in `ws`.
  /// \param ws    filled by `forward` of this network (batch B)
  /// \param dy    output adjoint, output_dim() × B
  /// \param grad  num_params(); **adds** (∂N/∂θ)ᵀ dY summed over the batch
  /// \param dx    null (gradient stopped at the input: that product is skipped), or set to
  ///              (∂N/∂x)ᵀ dY, input_dim() × B; must not alias `dy`
  void backward(const Workspace& ws, const Matrix<Scalar>& dy, Vector<Scalar>& grad,
                Matrix<Scalar>* dx) const {
    check_params_size();
    auto& packed = detail::packed_scratch<Scalar>();
    pack_layers(packed, false, true);
    backward_packed(ws, dy, grad, dx, packed);
  }

  /// The same with θ as packed by `pack` (which must have seen the current θ).
  void backward(const Workspace& ws, const Matrix<Scalar>& dy, Vector<Scalar>& grad,
                Matrix<Scalar>* dx, const PackedWeights& packed) const {
    check_packed(packed, true, "backward");
    backward_packed(ws, dy, grad, dx, packed.layers_);
  }

  /// The first half of `backward`: sets dX as `backward` does and records every layer's Δ in
  /// `adjoints`, leaving the parameter products to `add_param_gradient`. The halves touch
  /// disjoint data, so the engine runs the parameter products of one step on a second thread
  /// while this half of the next step proceeds; the sum is `backward`'s, bit for bit.
  void backward_inputs(const Workspace& ws, const Matrix<Scalar>& dy, Matrix<Scalar>* dx,
                       const PackedWeights& packed, LayerAdjoints& adjoints) const {
    check_packed(packed, true, "backward_inputs");
    inputs_packed(ws, dy, dx, packed.layers_, adjoints.record_);
  }

  /// The second half: **adds** (∂N/∂θ)ᵀ dY to `grad` from what `backward_inputs` recorded
  /// for the forward pass in `ws`.
  void add_param_gradient(const Workspace& ws, const LayerAdjoints& adjoints,
                          Vector<Scalar>& grad) const {
    check_recorded(ws, adjoints, grad);
    params_from(ws, adjoints.record_.deltas, grad);
  }

  /// The same for the seed dY·diag(s), `scales` = s (1 × B), from adjoints recorded with dY:
  /// every layer's Δ is linear in its sample's column of dY, so Δ_l·diag(s) are that seed's.
  /// They are formed in `scaled` (grown, never shrunk), which the caller owns so that its
  /// buffers do not depend on which thread makes the call.
  void add_param_gradient(const Workspace& ws, const LayerAdjoints& adjoints,
                          const Matrix<Scalar>& scales, LayerAdjoints& scaled,
                          Vector<Scalar>& grad) const {
    check_recorded(ws, adjoints, grad);
    detail::require(scales.rows() == 1 && scales.cols() == ws.batch_,
                    "Network::add_param_gradient: scales is ", scales.rows(), " × ",
                    scales.cols(), ", expected 1 × ", ws.batch_, " (one per sample)");
    detail::require(&scaled != &adjoints,
                    "Network::add_param_gradient: scaled is the recorded adjoints; expected "
                    "another LayerAdjoints");
    auto& scaled_deltas = scaled.record_.deltas;
    if (scaled_deltas.size() < layers_.size()) scaled_deltas.resize(layers_.size());
    params_from(ws, adjoints.record_.deltas, grad, scales.data(), &scaled_deltas);
  }

private:
  void forward_packed(const Matrix<Scalar>& x, Matrix<Scalar>& y, Workspace& ws,
                      const detail::PackedLayers<Scalar>& packed) const {
    check_input_rows(x, "forward");
    size_forward(x.cols(), ws);
    forward_range(x, 0, y, ws, packed);
  }

  void check_input_rows(const Matrix<Scalar>& x, const char* caller) const {
    detail::require(x.rows() == input_dim(), "Network::", caller, ": X has ", x.rows(),
                    " rows, expected input_dim() = ", input_dim(), " (one sample per column)");
  }

  /// Y = N(X) for the samples first … first + X.cols() − 1 of the workspace's batch.
  /// One machine copy (SBPTT_ONE_COPY), like `inputs_packed`: `forward` and `forward_columns`
  /// must give a sample the same outputs, whether the batch is evaluated whole or in parts.
  SBPTT_ONE_COPY void forward_range(const Matrix<Scalar>& x, Index first, Matrix<Scalar>& y,
                                    Workspace& ws,
                                    const detail::PackedLayers<Scalar>& packed) const {
    const Index count = x.cols();
    ws.input_.middleCols(first, count) = x;
    const Scalar* in = ws.input_.data() + first * ws.input_.rows();
    for (std::size_t l = 0; l < layers_.size(); ++l) {
      Scalar* out = ws.outputs_[l].data() + first * ws.outputs_[l].rows();
      const PackedMatrix<Scalar>& w = packed.weights[l];
      std::visit(
          [&](const auto& layer) {
            if constexpr (std::is_same_v<std::decay_t<decltype(layer)>, Conv1d>) {
              Matrix<Scalar>& columns = ws.columns_[l];
              layer.forward(w, in, count, out,
                            columns.data() + first * layer.output_length() * columns.rows());
            } else {
              layer.forward(w, in, count, out);
            }
          },
          layers_[l]);
      in = out;
    }
    y = ws.outputs_.back().middleCols(first, count);
  }

  /// Both halves, the layer adjoints kept in this thread's scratch.
  void backward_packed(const Workspace& ws, const Matrix<Scalar>& dy, Vector<Scalar>& grad,
                       Matrix<Scalar>* dx, const detail::PackedLayers<Scalar>& packed) const {
    check_grad_size(grad);
    auto& scratch = detail::network_scratch<Scalar>();
    inputs_packed(ws, dy, dx, packed, scratch);
    params_from(ws, scratch.deltas, grad);
  }

  /// Δ_l of every layer into `scratch.deltas` (its buffers grown, never shrunk) and, when `dx`
  /// is set, dX.
  /// One machine copy (SBPTT_ONE_COPY), like `params_from`: `backward` and the split halves
  /// must give the same bits, or the engine's results would depend on the thread count.
  SBPTT_ONE_COPY void inputs_packed(const Workspace& ws, const Matrix<Scalar>& dy,
                                    Matrix<Scalar>* dx,
                                    const detail::PackedLayers<Scalar>& packed,
                                    detail::NetworkScratch<Scalar>& scratch) const {
    ws.require_filled_by(*this);
    detail::require(dy.rows() == output_dim() && dy.cols() == ws.batch_,
                    "Network::backward: dY is ", dy.rows(), " × ", dy.cols(), ", expected ",
                    output_dim(), " × ", ws.batch_, " (output_dim() × batch of the forward pass)");
    auto& deltas = scratch.deltas;
    if (deltas.size() < layers_.size()) deltas.resize(layers_.size());
    const Index batch = ws.batch_;
    const Scalar* upstream = dy.data();  // ∂L/∂(output of layer l)
    bool upstream_is_delta = false;      // the product above applied layer l's derivative
    for (Index l = num_layers() - 1; l >= 0; --l) {
      const auto ul = static_cast<std::size_t>(l);
      const Layer& layer = layers_[ul];
      const Matrix<Scalar>& out = ws.outputs_[ul];
      auto delta = detail::grow_map(deltas[ul], out.rows(), batch);
      if (!upstream_is_delta) {
        if (layer_activation(layer) != Activation::Identity) {
          activation_backward(layer_activation(layer), out,
                              detail::ConstMatrixMap<Scalar>(upstream, out.rows(), batch), delta);
        } else if (upstream != delta.data()) {
          delta = detail::ConstMatrixMap<Scalar>(upstream, out.rows(), batch);
        }
      }

      // The input adjoint of layer 0 is dX; skipping it is what stops the gradient. Below
      // layer 0 it is the next layer's Δ itself when that layer is linear (no copy), or when
      // this layer is dense over a tanh layer: its product then applies the tanh's derivative
      // in registers (packed_product.hpp), saving a pass over the adjoint in memory.
      Scalar* d_in = nullptr;
      const Scalar* below_tanh_outputs = nullptr;
      if (l > 0) {
        const Layer& below = layers_[ul - 1];
        const Index rows = layer_output_dim(below);
        if (std::holds_alternative<Dense>(layer) &&
            layer_activation(below) == Activation::Tanh)
          below_tanh_outputs = ws.outputs_[ul - 1].data();
        d_in = layer_activation(below) == Activation::Identity || below_tanh_outputs != nullptr
                   ? detail::grow_map(deltas[ul - 1], rows, batch).data()
                   : detail::grow_map(scratch.adjoint, rows, batch).data();
      } else if (dx != nullptr) {
        dx->resize(input_dim(), batch);
        d_in = dx->data();
      }
      if (d_in == nullptr) break;

      const PackedMatrix<Scalar>& wt = packed.transposed[ul];
      std::visit(
          [&](const auto& spec) {
            if constexpr (std::is_same_v<std::decay_t<decltype(spec)>, Conv1d>) {
              spec.input_vjp(wt, delta.data(), batch, d_in, scratch.columns);
            } else {
              spec.input_vjp(wt, delta.data(), batch, d_in, below_tanh_outputs);
            }
          },
          layer);
      upstream = d_in;
      upstream_is_delta = below_tanh_outputs != nullptr;
    }
  }

  /// grad += the parameter products of every layer from the recorded Δ_l, or from Δ_l·diag(s)
  /// with `scales` = s (B): a register kernel scales a block of X once for all rows; elsewhere
  /// Δ_l·diag(s) is formed in `scaled`[l] (grown, never shrunk), which for a conv layer under
  /// the kernel holds s spread over its im2col columns instead. One machine copy
  /// (SBPTT_ONE_COPY): its callers pass constant null scales, for which a cloned copy could
  /// round differently.
  SBPTT_ONE_COPY void params_from(const Workspace& ws,
                                  const std::vector<Vector<Scalar>>& deltas,
                                  Vector<Scalar>& grad, const Scalar* scales = nullptr,
                                  std::vector<Vector<Scalar>>* scaled = nullptr) const {
    const Index batch = ws.batch_;
    for (std::size_t l = 0; l < layers_.size(); ++l) {
      Scalar* g = grad.data() + offsets_[l];
      const Scalar* delta = deltas[l].data();
      std::visit(
          [&](const auto& spec) {
            constexpr bool conv = std::is_same_v<std::decay_t<decltype(spec)>, Conv1d>;
            const Matrix<Scalar>& x = conv ? ws.columns_[l]
                                           : (l == 0 ? ws.input_ : ws.outputs_[l - 1]);
            if (scales == nullptr) return spec.param_vjp(x, delta, g);
            Vector<Scalar>& buffer = (*scaled)[l];
            if (outer_product_kernel_applies<Scalar>(x.rows())) {
              const Index per_sample = x.cols() / batch;  // a conv layer's positions P
              if (per_sample == 1) return spec.param_vjp(x, delta, g, scales);
              auto spread = detail::grow_map(buffer, per_sample, batch);
              spread = Eigen::Map<const Matrix<Scalar>>(scales, 1, batch).replicate(per_sample, 1);
              return spec.param_vjp(x, delta, g, buffer.data());
            }
            const Index rows = layer_output_dim(layers_[l]);
            detail::grow_map(buffer, rows, batch).noalias() =
                detail::ConstMatrixMap<Scalar>(delta, rows, batch) *
                Eigen::Map<const Vector<Scalar>>(scales, batch).asDiagonal();
            spec.param_vjp(x, buffer.data(), g);
          },
          layers_[l]);
    }
  }

  void check_recorded(const Workspace& ws, const LayerAdjoints& adjoints,
                      const Vector<Scalar>& grad) const {
    ws.require_filled_by(*this);
    check_grad_size(grad);
    adjoints.require_recorded_for(layers_, ws.batch_);
  }

  void check_grad_size(const Vector<Scalar>& grad) const {
    detail::require(grad.size() == num_params(), "Network::backward: grad has ", grad.size(),
                    " entries, expected num_params() = ", num_params());
  }

  /// Packs W with b (`weights`) and/or Wᵀ (`transposed`) of every layer from θ.
  void pack_layers(detail::PackedLayers<Scalar>& packed, bool weights, bool transposed) const {
    packed.count = layers_.size();
    if (packed.weights.size() < packed.count) {
      packed.weights.resize(packed.count);
      packed.transposed.resize(packed.count);
    }
    for (std::size_t l = 0; l < layers_.size(); ++l) {
      const Index rows = layer_weight_rows(layers_[l]);
      const Index cols = layer_weight_count(layers_[l]) / rows;
      const Scalar* theta = params_.data() + offsets_[l];
      if (weights) packed.weights[l].pack(theta, rows, cols, false, theta + rows * cols);
      if (transposed) packed.transposed[l].pack(theta, rows, cols, true);
    }
  }

  /// Refuses packed weights that are not this network's (network_workspace.hpp).
  void check_packed(const PackedWeights& packed, bool transposed, const char* caller) const {
    check_params_size();
    packed.require_fit(layers_, transposed, caller);
  }

  void check_params_size() const {
    detail::require(params_.size() == num_params(), "Network: params() has ", params_.size(),
                    " entries, expected num_params() = ", num_params());
  }

  std::vector<Layer> layers_;
  std::vector<Index> offsets_;  // first parameter of each layer
  Vector<Scalar> params_;
};

static_assert(static_assert_controller<Network<double>>());
static_assert(static_assert_controller<Network<float>>());
static_assert(Controller<Network<double>> && Controller<Network<float>>);
static_assert(PackingController<Network<double>> && PackingController<Network<float>>);
static_assert(SeedScalingController<Network<double>> && SeedScalingController<Network<float>>);
static_assert(ColumnSplitController<Network<double>> && ColumnSplitController<Network<float>>);

}  // namespace sbptt
