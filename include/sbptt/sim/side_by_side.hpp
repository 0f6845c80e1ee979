#pragma once
/// \file Two batch matrices of one shape read and written as one, and the argument checks of
/// a simulator's `vjp_batch_pair` (core/concepts.hpp, `PairedBatchSimulator`), which hands
/// the combined update's two sweeps to one call this way.
#include <array>
#include <cstddef>

#include "sbptt/core/error.hpp"
#include "sbptt/core/types.hpp"

namespace sbptt::detail {

/// Two batch matrices of one shape read and written as one, [a b]: column j is column j of a
/// for j < a.cols(), else column j − a.cols() of b; or a alone (`right` null). The combined
/// update's pair hands a simulator both sweeps' adjoints at the same states this way, in one
/// block of lanes, without forming [x x] and [λ₁ λ₂] (`GuidanceByRepulsion::vjp_batch_pair`).
/// `M` is `const Matrix<Scalar>` to read, `Matrix<Scalar>` to write.
template <class M>
struct SideBySide {
  M* left = nullptr;
  M* right = nullptr;

  [[nodiscard]] Index rows() const { return left->rows(); }
  [[nodiscard]] Index cols() const { return right == nullptr ? left->cols() : 2 * left->cols(); }
  /// Where column j starts.
  [[nodiscard]] auto* column(Index j) const {
    const Index half = left->cols();
    return j < half ? left->data() + j * rows() : right->data() + (j - half) * rows();
  }
};

/// The outputs of a `vjp_batch_pair` call by `caller` on inputs x, u, λ₁, λ₂, checked and then
/// sized: each pair (λx₁, λx₂) and (λu₁, λu₂) both null or both set, and every output a
/// matrix of its own, none of the inputs, since one block of lanes would write it before a
/// later block reads that input's columns for the other half. λx to `state_dim` × B, λu to
/// `control_dim` × B, B = x.cols(). Nothing is resized unless every check passes.
template <class Scalar>
void size_paired_outputs(const char* caller, const Matrix<Scalar>& x, const Matrix<Scalar>& u,
                         const Matrix<Scalar>& lambda_1, const Matrix<Scalar>& lambda_2,
                         const std::array<Matrix<Scalar>*, 2>& lambda_x,
                         const std::array<Matrix<Scalar>*, 2>& lambda_u, Index state_dim,
                         Index control_dim) {
  const std::array<const Matrix<Scalar>*, 8> matrices{
      &x, &u, &lambda_1, &lambda_2, lambda_x[0], lambda_x[1], lambda_u[0], lambda_u[1]};
  constexpr std::array<const char*, 8> names{"x",          "u",          "lambda_1",
                                             "lambda_2",   "lambda_x_1", "lambda_x_2",
                                             "lambda_u_1", "lambda_u_2"};
  for (std::size_t i = 4; i < matrices.size(); ++i)
    for (std::size_t j = 0; j < i; ++j)
      require(matrices[i] == nullptr || matrices[i] != matrices[j], caller, ": ", names[i],
              " is ", names[j], "; expected a matrix of its own");
  for (std::size_t i = 4; i < matrices.size(); i += 2)
    require((matrices[i] == nullptr) == (matrices[i + 1] == nullptr), caller, ": ", names[i],
            matrices[i] == nullptr ? " is null and " : " is set and ", names[i + 1],
            matrices[i] == nullptr ? " is set" : " is null", "; expected both null or both set");
  for (Matrix<Scalar>* out : lambda_x)
    if (out != nullptr) out->resize(state_dim, x.cols());
  for (Matrix<Scalar>* out : lambda_u)
    if (out != nullptr) out->resize(control_dim, x.cols());
}

}  // namespace sbptt::detail
