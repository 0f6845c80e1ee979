#pragma once
/// \file Fully connected layer `y = f(W x + b)`.
///
/// Parameter layout inside the flat vector (docs/formats.md, PyTorch `Linear` order): the weight W
/// (outputs × inputs) row-major, then the bias b (outputs). The layer reads and writes its slice
/// through `Eigen::Map`s; the products with W and Wᵀ use copies packed once per parameter
/// update (packed_product.hpp), the product for dW a register-blocked kernel (outer_product.hpp).
#include <span>
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

  /// Adds the parameter VJPs of `terms` to `grad` (this layer's slice, num_params() entries),
  /// in their order: a batch each, D the adjoint of the pre-activation ∂L/∂(W x + b), n_out ×
  /// B, and X the inputs the forward pass saw, n_in × B (both column-major); a factor per
  /// sample on D only where the register kernel runs (`outer_product_kernel_applies(inputs)`).
  template <class Scalar>
  void param_vjp(std::span<const OuterProductTerm<Scalar>> terms, Scalar* grad) const {
    // The batch sum is the inner dimension of these products (outer_product.hpp).
    add_weight_and_bias_products(grad, outputs, inputs, terms);
  }

  /// Writes the input VJP ∂L/∂x = Wᵀ Δ, n_in × B (column-major), into `dx`.
  /// \param wt  Wᵀ, packed (`Network::pack` makes it)
  template <class Scalar>
  void input_vjp(const PackedMatrix<Scalar>& wt, const Scalar* delta, Index batch,
                 Scalar* dx) const {
    wt.multiply(delta, outputs, batch, dx, inputs);
  }
};

}  // namespace sbptt
