#pragma once
/// \file LU factorisation (Thomas' algorithm) of a tridiagonal matrix with constant
/// off-diagonals, and solves with the matrix and with its conjugate transpose from that one
/// factorisation. O(n) to factor, O(n) per solve, no heap allocation when `Size` is fixed.
///
///     T = L·U,  L unit lower bidiagonal with sub-diagonal l_j = a / p_{j−1},
///               U upper bidiagonal with diagonal p_j and super-diagonal c,
///     p_0 = d_0,  p_j = d_j − a·c / p_{j−1}        (a: sub-diagonal, c: super-diagonal)
///
/// Tᴴ = Uᴴ·Lᴴ, so the adjoint solve is a forward sweep with Uᴴ (lower bidiagonal, diagonal
/// conj(p_j), sub-diagonal conj(c)) followed by a backward sweep with Lᴴ (unit upper,
/// super-diagonal conj(l_{j+1})): the adjoint of a linear solve reuses the same factors.
///
/// There is no pivoting: the caller guarantees that no leading principal minor vanishes. For
/// the Crank–Nicolson matrix I + iK (K real symmetric) this holds because the Hermitian part of
/// every leading block is the identity, so vᴴ(I + iK)v has real part ‖v‖² ≠ 0 for v ≠ 0.
#include <cmath>
#include <complex>

#include "sbptt/core/error.hpp"
#include "sbptt/core/types.hpp"

namespace sbptt {

namespace detail {
template <class T>
[[nodiscard]] T conj_if_complex(const T& z) {
  if constexpr (Eigen::NumTraits<T>::IsComplex) {
    return std::conj(z);
  } else {
    return z;
  }
}
/// 1/z, for complex z as conj(z)/|z|² with |z|² = Re² + Im², inline. std::complex's division is
/// a library call (libgcc's __divsc3) that rescales against under- and overflow of |z|²; it is
/// kept for the pivots where |z|² leaves the normal range (|z| outside about 1e-19 … 1e19 in
/// float), which the Crank–Nicolson pivots (|z| ≥ 1) never do. A third of the quantum step.
template <class T>
[[nodiscard]] T reciprocal(const T& z) {
  if constexpr (Eigen::NumTraits<T>::IsComplex) {
    const auto squared_norm = z.real() * z.real() + z.imag() * z.imag();
    if (!std::isnormal(squared_norm)) return T(1) / z;
    return T(z.real() / squared_norm, -z.imag() / squared_norm);
  } else {
    return T(1) / z;
  }
}
}  // namespace detail

/// Factorised tridiagonal matrix with diagonal d (size n) and constant sub- and
/// super-diagonals a and c. `T` is real or std::complex; `Size` is n or Eigen::Dynamic.
template <class T, int Size = Eigen::Dynamic>
class ConstantTridiagonalLu {
public:
  using Vector = Eigen::Matrix<T, Size, 1>;

  /// Factors the matrix with diagonal `diag` (n), sub-diagonal `lower`, super-diagonal `upper`.
  /// Throws InvalidArgument if a pivot is exactly zero (a singular leading minor).
  ConstantTridiagonalLu(const Vector& diag, T lower, T upper) : lower_(lower), upper_(upper) {
    const Index n = diag.size();
    inv_pivot_.resize(n);
    for (Index j = 0; j < n; ++j) {
      const T pivot = j == 0 ? diag(0) : diag(j) - lower_ * upper_ * inv_pivot_(j - 1);
      detail::require(pivot != T(0), "ConstantTridiagonalLu: pivot ", j,
                      " is zero; expected non-singular leading minors (no pivoting is done)");
      inv_pivot_(j) = detail::reciprocal(pivot);
    }
  }

  [[nodiscard]] Index size() const { return inv_pivot_.size(); }

  /// Overwrites `rhs` (n) with T⁻¹ rhs.
  void solve_in_place(Vector& rhs) const {
    const Index n = size();
    for (Index j = 1; j < n; ++j) rhs(j) -= lower_ * inv_pivot_(j - 1) * rhs(j - 1);  // L⁻¹
    if (n > 0) rhs(n - 1) *= inv_pivot_(n - 1);                                        // U⁻¹
    for (Index j = n - 2; j >= 0; --j) rhs(j) = (rhs(j) - upper_ * rhs(j + 1)) * inv_pivot_(j);
  }

  /// Overwrites `rhs` (n) with T⁻ᴴ rhs (the conjugate transpose; the transpose for real T).
  void adjoint_solve_in_place(Vector& rhs) const {
    using detail::conj_if_complex;
    const Index n = size();
    const T upper_h = conj_if_complex(upper_);
    if (n > 0) rhs(0) *= conj_if_complex(inv_pivot_(0));  // Uᴴ⁻¹, forward
    for (Index j = 1; j < n; ++j)
      rhs(j) = (rhs(j) - upper_h * rhs(j - 1)) * conj_if_complex(inv_pivot_(j));
    for (Index j = n - 2; j >= 0; --j)  // Lᴴ⁻¹, backward: (Lᴴ)_{j,j+1} = conj(l_{j+1})
      rhs(j) -= conj_if_complex(lower_ * inv_pivot_(j)) * rhs(j + 1);
  }

private:
  Vector inv_pivot_;  // 1 / p_j: one division per row at factor time, none per solve
  T lower_;
  T upper_;
};

}  // namespace sbptt
