#pragma once
/// \file 1-D convolution (cross-correlation, as in PyTorch and Keras), stride s, valid padding.
///
/// A sample has L positions × C_in channels and is stored POSITION-MAJOR in its column:
/// entry (p, c) at row p·C_in + c. The output (P positions × C_out channels,
/// P = (L − K)/s + 1, trailing positions that do not fill a window are dropped) uses the same
/// layout, so flattening a conv output for a following dense layer costs nothing: the column
/// already *is* the position-major flatten of docs/formats.md.
///
/// Parameter layout (PyTorch `Conv1d` order): weight (C_out × C_in × K) row-major, then the
/// bias (C_out). Read as a C_out × (C_in·K) row-major matrix W, with column index c·K + j:
///
///     y(p, o) = f( b_o + Σ_c Σ_j W(o, c·K + j) · x(p·s + j, c) ).
///
/// The implementation gathers every window into a (C_in·K) × (P·B) matrix (im2col) so that the
/// layer is ONE matrix product per batch; per-element loops would be an order of magnitude
/// slower at the quantum-control sizes (60 channels).
#include <string>
#include <type_traits>

#include "sbptt/core/error.hpp"
#include "sbptt/core/types.hpp"
#include "sbptt/nn/activation.hpp"
#include "sbptt/nn/outer_product.hpp"
#include "sbptt/nn/packed_product.hpp"

namespace sbptt {

/// Sizes, stride and activation of a 1-D convolution layer; the math is in its member templates.
struct Conv1d {
  Index length = 0;        ///< L, input positions
  Index in_channels = 0;   ///< C_in
  Index out_channels = 0;  ///< C_out (number of filters)
  Index kernel = 0;        ///< K, window width in positions
  Index stride = 1;        ///< s
  Activation activation = Activation::Identity;  ///< f (linear by default, as in Keras/PyTorch)

  /// P = (L − K)/s + 1 (valid padding).
  [[nodiscard]] Index output_length() const { return (length - kernel) / stride + 1; }
  [[nodiscard]] Index input_dim() const { return length * in_channels; }
  [[nodiscard]] Index output_dim() const { return output_length() * out_channels; }
  /// Rows of one im2col column: one window, C_in·K.
  [[nodiscard]] Index window_size() const { return in_channels * kernel; }
  /// Rows of the weight read as a matrix (out_channels); its columns are weight_count() / this.
  [[nodiscard]] Index weight_rows() const { return out_channels; }
  [[nodiscard]] Index weight_count() const { return out_channels * window_size(); }
  [[nodiscard]] Index num_params() const { return weight_count() + out_channels; }

  /// Glorot fans, Keras `Conv1D` convention: (C_in·K, C_out·K).
  [[nodiscard]] Index fan_in() const { return in_channels * kernel; }
  [[nodiscard]] Index fan_out() const { return out_channels * kernel; }

  /// e.g. "conv1d 32×2→15×60 k3 s2 tanh" (positions × channels).
  [[nodiscard]] std::string describe() const {
    return detail::concat("conv1d ", length, "×", in_channels, "→", output_length(), "×",
                          out_channels, " k", kernel, " s", stride, " ", to_string(activation));
  }

  /// Throws `InvalidArgument` unless the sizes give at least one output position.
  void validate() const {
    detail::require(in_channels > 0, "Conv1d: in_channels = ", in_channels, ", expected > 0");
    detail::require(out_channels > 0, "Conv1d: out_channels = ", out_channels, ", expected > 0");
    detail::require(kernel > 0, "Conv1d: kernel = ", kernel, ", expected > 0");
    detail::require(stride > 0, "Conv1d: stride = ", stride, ", expected > 0");
    detail::require(length >= kernel, "Conv1d: length = ", length,
                    ", expected >= kernel = ", kernel, " (valid padding needs one full window)");
  }

  /// Gathers the windows of a batch into `columns`, (C_in·K) × (P·B): column b·P + p holds
  /// window p of sample b with row c·K + j = x(p·s + j, c), matching the weight's row layout.
  /// \param x  inputs, (L·C_in) × B, position-major
  template <class Scalar>
  void im2col(const Scalar* x, Index batch, Scalar* columns) const {
    // In memory a window is K positions of C_in channels (position-major); the weight wants
    // it channel-major (c·K + j), hence the small transpose.
    for_each_window(batch, columns, x, [&](Scalar* column, const Scalar* win, auto k) {
      for (Index c = 0; c < in_channels; ++c)
        for (Index j = 0; j < k; ++j) column[c * k + j] = win[j * in_channels + c];
    });
  }

  /// Calls `f(k)` with the kernel width k as a compile-time constant for K ≤ 5, else as an
  /// Index. With a fixed K the window transposes of im2col and col2im become whole-register
  /// shuffles. Eigen's transpose of a C_in × K map, used before, took 2 and 11 times as long
  /// for the im2col of the paper's two layers at a batch of 8 (500 against 236 ns, 6.1 µs
  /// against 0.56 µs for 60 channels, K = 3).
  template <class F>
  void with_kernel_width(F&& f) const {
    switch (kernel) {
      case 1: return f(std::integral_constant<Index, 1>{});
      case 2: return f(std::integral_constant<Index, 2>{});
      case 3: return f(std::integral_constant<Index, 3>{});
      case 4: return f(std::integral_constant<Index, 4>{});
      case 5: return f(std::integral_constant<Index, 5>{});
      default: return f(kernel);
    }
  }

  /// Calls `f(column, window, k)` for window p of sample b, for every b < `batch` and p:
  /// `column` is column b·P + p of the im2col matrix at `columns`, `window` the window's first
  /// entry in the position-major samples at `samples` (input_dim() apart), k the kernel width.
  template <class ColumnPtr, class SamplePtr, class F>
  void for_each_window(Index batch, ColumnPtr columns, SamplePtr samples, F&& f) const {
    const Index positions = output_length();
    const Index window = window_size();
    with_kernel_width([&](auto k) {
      for (Index b = 0; b < batch; ++b)
        for (Index p = 0; p < positions; ++p)
          f(columns + (b * positions + p) * window,
            samples + b * input_dim() + p * stride * in_channels, k);
    });
  }

  /// Y = f(conv(X) + b) for a batch.
  /// \param w        W with b, packed (packed_product.hpp; `Network::pack` makes it)
  /// \param x        inputs, (L·C_in) × B, position-major
  /// \param batch    B
  /// \param y        outputs, (P·C_out) × B, position-major (overwritten)
  /// \param columns  im2col workspace, (C_in·K) × (P·B) (overwritten); backward needs it
  template <class Scalar>
  void forward(const PackedMatrix<Scalar>& w, const Scalar* x, Index batch, Scalar* y,
               Scalar* columns) const {
    im2col(x, batch, columns);
    // A C_out × (P·B) column-major matrix has exactly the memory of the position-major
    // (P·C_out) × B output, so the product writes the result in place.
    w.multiply(columns, window_size(), output_length() * batch, y, out_channels);
    activate_in_place(activation, y, output_dim() * batch);
  }

  /// Adds the parameter VJP of a batch to `grad`.
  /// \param columns  the im2col matrix of the forward pass, (C_in·K) × (P·B)
  /// \param delta    adjoint of the pre-activation, (P·C_out) × B position-major, equivalently
  ///                 C_out × (P·B) column-major
  /// \param grad     this layer's slice of the gradient, num_params() entries; accumulated
  /// \param scale    null, or a factor per im2col column (P·B: sample b's at b·P … b·P + P − 1)
  ///                 on its delta, where the register kernel runs
  template <class Scalar>
  void param_vjp(const Matrix<Scalar>& columns, const Scalar* delta, Scalar* grad,
                 const Scalar* scale = nullptr) const {
    add_weight_and_bias_products(grad, out_channels, window_size(), delta, columns.data(),
                                 columns.cols(), scale);
  }

  /// Writes the input VJP ∂L/∂x, (L·C_in) × B position-major, into `dx`.
  /// \param wt       Wᵀ, packed (`Network::pack` makes it)
  /// \param scratch  grown to hold the (C_in·K) × (P·B) window adjoints
  template <class Scalar>
  void input_vjp(const PackedMatrix<Scalar>& wt, const Scalar* delta, Index batch, Scalar* dx,
                 Vector<Scalar>& scratch) const {
    const Index positions = output_length();
    const Index window = window_size();
    auto dcols = detail::grow_map(scratch, window, positions * batch);
    wt.multiply(delta, out_channels, positions * batch, dcols.data(), window);
    // col2im: overlapping windows (K > s) add up; positions past the last window stay zero.
    detail::MatrixMap<Scalar> dxm(dx, input_dim(), batch);
    dxm.setZero();
    for_each_window(batch, dcols.data(), dx, [&](const Scalar* column, Scalar* win, auto k) {
      for (Index c = 0; c < in_channels; ++c)
        for (Index j = 0; j < k; ++j) win[j * in_channels + c] += column[c * k + j];
    });
  }
};

}  // namespace sbptt
