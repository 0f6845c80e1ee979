#pragma once
/// \file Fully connected layer `y = f(W x + b)`.
///
/// Parameter layout inside the flat vector (docs/formats.md, PyTorch `Linear` order): the weight W
/// (outputs × inputs) row-major, then the bias b (outputs). The layer reads and writes its slice
/// through `Eigen::Map`s; the products with W and Wᵀ use copies packed once per parameter
/// update (packed_product.hpp), the product for dW a register-blocked kernel (outer_product.hpp).
#include <string>

#include "sbptt/core/error.hpp"
#include "sbptt/core/types.hpp"
#include "sbptt/nn/activation.hpp"
#include "sbptt/nn/outer_product.hpp"
#include "sbptt/nn/packed_product.hpp"

namespace sbptt {

/// Sizes and activation of a dense layer; the math is in its member templates.
struct Dense {
  Index inputs = 0;                           ///< n_in, length of x
  Index outputs = 0;                          ///< n_out, length of y
  Activation activation = Activation::Identity;  ///< f (linear by default, as in Keras/PyTorch)

  [[nodiscard]] Index input_dim() const { return inputs; }
  [[nodiscard]] Index output_dim() const { return outputs; }
  /// Rows of the weight read as a matrix (outputs); its columns are weight_count() / this.
  [[nodiscard]] Index weight_rows() const { return outputs; }
  [[nodiscard]] Index weight_count() const { return outputs * inputs; }
  [[nodiscard]] Index num_params() const { return weight_count() + outputs; }

  /// Glorot fans: (n_in, n_out).
  [[nodiscard]] Index fan_in() const { return inputs; }
  [[nodiscard]] Index fan_out() const { return outputs; }

  /// e.g. "dense 24→100 tanh".
  [[nodiscard]] std::string describe() const {
    return detail::concat("dense ", inputs, "→", outputs, " ", to_string(activation));
  }

  /// Throws `InvalidArgument` unless both sizes are positive.
  void validate() const {
    detail::require(inputs > 0, "Dense: inputs = ", inputs, ", expected > 0");
    detail::require(outputs > 0, "Dense: outputs = ", outputs, ", expected > 0");
  }

  /// Y = f(W X + b) for a batch.
  /// \param w      W with b, packed (packed_product.hpp; `Network::pack` makes it)
  /// \param x      inputs, n_in × B, column-major
  /// \param batch  B
  /// \param y      outputs, n_out × B, column-major (overwritten; must not overlap `x`)
  template <class Scalar>
  void forward(const PackedMatrix<Scalar>& w, const Scalar* x, Index batch, Scalar* y) const {
    w.multiply(x, inputs, batch, y, outputs);
    activate_in_place(activation, y, outputs * batch);
  }

  /// Adds the parameter VJP of a batch to `grad`.
  /// \param x      the inputs the forward pass saw, n_in × B
  /// \param delta  adjoint of the pre-activation ∂L/∂(W x + b), n_out × B (column-major)
  /// \param grad   this layer's slice of the gradient, num_params() entries; accumulated
  /// \param scale  null, or a factor per sample (B) on its delta, where the register kernel
  ///               runs (`outer_product_kernel_applies(inputs)`)
  template <class Scalar>
  void param_vjp(const Matrix<Scalar>& x, const Scalar* delta, Scalar* grad,
                 const Scalar* scale = nullptr) const {
    // The batch sum is the inner dimension of these products (outer_product.hpp).
    add_weight_and_bias_products(grad, outputs, inputs, delta, x.data(), x.cols(), scale);
  }

  /// Writes the input VJP ∂L/∂x = Wᵀ Δ, n_in × B (column-major), into `dx`; or, given the
  /// outputs T of a tanh layer below (n_in × B), that layer's Δ = (Wᵀ Δ) ⊙ (1 − T²).
  /// \param wt  Wᵀ, packed (`Network::pack` makes it)
  template <class Scalar>
  void input_vjp(const PackedMatrix<Scalar>& wt, const Scalar* delta, Index batch, Scalar* dx,
                 const Scalar* below_tanh_outputs = nullptr) const {
    wt.multiply(delta, outputs, batch, dx, inputs, below_tanh_outputs);
  }
};

}  // namespace sbptt
