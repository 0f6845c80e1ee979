#pragma once
/// \file bench's Network wrapper that counts the multiply-adds it executes (the GFLOP column).

#include <atomic>
#include <type_traits>
#include <variant>

#include <sbptt/sbptt.hpp>

namespace bench {

using sbptt::Index;
using sbptt::Matrix;
using sbptt::Network;

/// A `Network` seen through the Controller concept, counting the multiply-adds it executes.
template <class S>
class CountingNetwork {
public:
  using Scalar = S;
  using Workspace = typename Network<S>::Workspace;
  using PackedWeights = typename Network<S>::PackedWeights;
  using LayerAdjoints = typename Network<S>::LayerAdjoints;

  explicit CountingNetwork(Network<S>& net) : net_(net) {
    for (const auto& layer : net.layers()) {
      const Index macs = std::visit(
          [](const auto& l) -> Index {
            if constexpr (std::is_same_v<std::decay_t<decltype(l)>, sbptt::Conv1d>) {
              return l.output_length() * l.out_channels * l.in_channels * l.kernel;
            } else {
              return l.inputs * l.outputs;
            }
          },
          layer);
      per_sample_ += macs;
      if (&layer != &net.layers().front()) hidden_input_ += macs;
    }
    first_input_ = per_sample_ - hidden_input_;
  }

  [[nodiscard]] Index input_dim() const { return net_.input_dim(); }
  [[nodiscard]] Index output_dim() const { return net_.output_dim(); }
  [[nodiscard]] Index num_params() const { return net_.num_params(); }
  [[nodiscard]] const sbptt::Vector<S>& params() const { return net_.params(); }
  [[nodiscard]] sbptt::Vector<S>& params() { return net_.params(); }

  void pack(PackedWeights& packed) const { net_.pack(packed); }
  void forward(const Matrix<S>& x, Matrix<S>& y, Workspace& ws) const {
    net_.forward(x, y, ws);
    macs_.fetch_add(per_sample_ * x.cols(), std::memory_order_relaxed);
  }
  void forward(const Matrix<S>& x, Matrix<S>& y, Workspace& ws,
               const PackedWeights& packed) const {
    net_.forward(x, y, ws, packed);
    macs_.fetch_add(per_sample_ * x.cols(), std::memory_order_relaxed);
  }
  /// The forward pass in parts: counted once for the whole batch here, as its parts cover the
  /// batch once, so that the parts on several threads do not contend for the counter.
  void size_forward(Index batch, Workspace& ws) const {
    net_.size_forward(batch, ws);
    macs_.fetch_add(per_sample_ * batch, std::memory_order_relaxed);
  }
  void forward_columns(const Matrix<S>& x, Index first, Matrix<S>& y, Workspace& ws,
                       const PackedWeights& packed) const {
    net_.forward_columns(x, first, y, ws, packed);
  }
  /// Parameter VJP of every layer, input VJP of every layer but the first, and of the first
  /// one only when dX is asked for (exactly what `Network::backward` executes).
  void backward(const Workspace& ws, const Matrix<S>& dy, sbptt::Vector<S>& grad,
                Matrix<S>* dx) const {
    net_.backward(ws, dy, grad, dx);
    count_backward(dy.cols(), dx != nullptr);
  }
  void backward(const Workspace& ws, const Matrix<S>& dy, sbptt::Vector<S>& grad, Matrix<S>* dx,
                const PackedWeights& packed) const {
    net_.backward(ws, dy, grad, dx, packed);
    count_backward(dy.cols(), dx != nullptr);
  }

  /// The two halves of the packed `backward`, counted as they split its products.
  void backward_inputs(const Workspace& ws, const Matrix<S>& dy, Matrix<S>* dx,
                       const PackedWeights& packed, LayerAdjoints& adjoints) const {
    net_.backward_inputs(ws, dy, dx, packed, adjoints);
    macs_.fetch_add((hidden_input_ + (dx != nullptr ? first_input_ : 0)) * dy.cols(),
                    std::memory_order_relaxed);
  }
  void add_param_gradient(const Workspace& ws, const LayerAdjoints& adjoints,
                          sbptt::Vector<S>& grad) const {
    net_.add_param_gradient(ws, adjoints, grad);
    macs_.fetch_add(per_sample_ * ws.batch_size(), std::memory_order_relaxed);
  }
  void add_param_gradient(const Workspace& ws, const LayerAdjoints& adjoints,
                          const Matrix<S>& scales, LayerAdjoints& scaled,
                          sbptt::Vector<S>& grad) const {
    net_.add_param_gradient(ws, adjoints, scales, scaled, grad);
    macs_.fetch_add(per_sample_ * ws.batch_size(), std::memory_order_relaxed);
  }

  [[nodiscard]] long long macs() const { return macs_.load(); }
  void reset() { macs_ = 0; }

private:
  void count_backward(Index batch, bool input_vjp) const {
    const Index per = per_sample_ + hidden_input_ + (input_vjp ? first_input_ : 0);
    macs_.fetch_add(per * batch, std::memory_order_relaxed);
  }

  Network<S>& net_;
  Index per_sample_ = 0, hidden_input_ = 0, first_input_ = 0;
  mutable std::atomic<long long> macs_{0};
};

static_assert(sbptt::SeedScalingController<CountingNetwork<float>> &&
                  sbptt::ColumnSplitController<CountingNetwork<float>>,
              "bench must time the engine's split and shared-seed backward and its forward pass "
              "in parts, as a Network gets them");

}  // namespace bench
