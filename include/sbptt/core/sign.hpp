#pragma once
/// \file TF's sign and the sign agreement of two vectors: the one definition the combined
/// update (optim) and the diagnostics (bptt) share.
///
///     sign(x) = −1, 0 or +1 (sign(0) = 0, as tf.sign)
///     agree(m, r) = sign(m) == sign(r), and false when m or r is NaN
///     agreement(g_M, g_R) = #{i : agree(g_M[i], g_R[i])} / n, and 1 for n = 0
///
/// Two zeros agree; one zero and one non-zero do not. NaN never agrees: for g_R this is what TF
/// does (an overflowing component is masked out); for g_M it keeps a NaN out of the optimizer.
/// An empty pair of vectors has nothing that disagrees, hence 1.
#include <bit>
#include <cmath>
#include <concepts>
#include <type_traits>

#include <Eigen/Core>

#include "sbptt/core/error.hpp"
#include "sbptt/core/non_finite.hpp"
#include "sbptt/core/types.hpp"

#if defined(EIGEN_VECTORIZE_AVX512)
#include <immintrin.h>
#endif

namespace sbptt {
namespace detail {

/// TF's sign for real numbers: −1, 0 or +1; 0 for NaN, so callers test NaN with `signs_agree`.
template <std::floating_point Scalar>
[[nodiscard]] int tf_sign(Scalar x) {
  return static_cast<int>(x > Scalar(0)) - static_cast<int>(x < Scalar(0));
}

/// Whether component i keeps g_M under the combination rule (see the file comment): both
/// positive, both negative or both zero, which every comparison with a NaN fails. Written as
/// three comparisons joined without branches, so that the loops over a gradient (11301
/// components for the cart pole) vectorise: with `isnan` and `tf_sign` they ran one component
/// at a time, 14 µs for the combined update's step and as much for its diagnostics.
template <std::floating_point Scalar>
[[nodiscard]] bool signs_agree(Scalar modified, Scalar regular) {
  const Scalar zero(0);
#if defined(__FINITE_MATH_ONLY__) && __FINITE_MATH_ONLY__
  // There the compiler may take a NaN to compare like a number (GCC 12 counted NaN against 0
  // as agreeing), so NaN is told by its bits.
  if (nan_by_bits(modified) || nan_by_bits(regular)) return false;
#endif
  return ((modified > zero) & (regular > zero)) | ((modified < zero) & (regular < zero)) |
         ((modified == zero) & (regular == zero));
}

#if defined(EIGEN_VECTORIZE_AVX512)
/// The lanes where g_M and g_R both satisfy `Predicate` against 0 (ordered: false for NaN),
/// the second comparison under the mask of the first.
template <int Predicate>
EIGEN_ALWAYS_INLINE __mmask16 both_lanes(__m512 modified, __m512 regular) {
  const __m512 zero = _mm512_setzero_ps();
  return _mm512_mask_cmp_ps_mask(_mm512_cmp_ps_mask(modified, zero, Predicate), regular, zero,
                                 Predicate);
}
template <int Predicate>
EIGEN_ALWAYS_INLINE __mmask8 both_lanes(__m512d modified, __m512d regular) {
  const __m512d zero = _mm512_setzero_pd();
  return _mm512_mask_cmp_pd_mask(_mm512_cmp_pd_mask(modified, zero, Predicate), regular, zero,
                                 Predicate);
}

/// `signs_agree` for every lane of two registers: the same three comparisons.
template <class Packet>
EIGEN_ALWAYS_INLINE auto agreeing_lanes(Packet modified, Packet regular) {
  using Mask = decltype(both_lanes<_CMP_GT_OQ>(modified, regular));
  return static_cast<Mask>(both_lanes<_CMP_GT_OQ>(modified, regular) |
                           both_lanes<_CMP_LT_OQ>(modified, regular) |
                           both_lanes<_CMP_EQ_OQ>(modified, regular));
}
#endif

/// Σ g_M·g_R, Σ g_M² and Σ g_R², each summed lane-wise over whole registers and then across the
/// lanes, the remaining components after in order.
template <class Scalar>
struct PairSums {
  Scalar dot = 0, modified_norm2 = 0, regular_norm2 = 0;
};

/// Whether `agreement_pass` sums in registers (AVX-512, float or double). Elsewhere its sums go
/// one component at a time, and Eigen's reductions are faster.
template <class Scalar>
inline constexpr bool pair_sums_in_registers =
#if defined(EIGEN_VECTORIZE_AVX512)
    FloatOrDouble<Scalar>;
#else
    false;
#endif

/// One pass over g_M and g_R (n components each): returns how many agree, writes the combined
/// vector (g_M where they agree, else 0) to `combined` unless it is null (it may be either
/// input: each register is read before it is written), and adds the sums to `sums` unless it
/// is null. Two gradients of guidance's network (13,004 floats each) do not fit in L1, and a
/// pass over them costs about as much as reading them, so `compare` reads both once instead of
/// four times (2.8 µs → 1.1 µs); with AVX-512 a register's agreement is a mask and its count a
/// popcount (`sign_agreement` 1.45 → 1.05 µs, the combined update's pass 1.5 → 1.2).
template <std::floating_point Scalar>
Index agreement_pass(const Scalar* modified, const Scalar* regular, Index n, Scalar* combined,
                     PairSums<Scalar>* sums) {
  Index agreeing = 0;
  Index i = 0;
#if defined(EIGEN_VECTORIZE_AVX512)
  if constexpr (pair_sums_in_registers<Scalar>) {
    namespace ei = Eigen::internal;
    using Packet = typename ei::packet_traits<Scalar>::type;
    constexpr auto lanes = static_cast<Index>(64 / sizeof(Scalar));
    Packet dot = ei::pset1<Packet>(Scalar(0)), m2 = dot, r2 = dot;
    for (; i + lanes <= n; i += lanes) {
      const Packet m = ei::ploadu<Packet>(modified + i);
      const Packet r = ei::ploadu<Packet>(regular + i);
      const auto keep = agreeing_lanes(m, r);
      agreeing += std::popcount(static_cast<unsigned>(keep));
      if (combined != nullptr) {
        if constexpr (std::is_same_v<Scalar, float>) {
          _mm512_storeu_ps(combined + i, _mm512_maskz_mov_ps(keep, m));
        } else {
          _mm512_storeu_pd(combined + i, _mm512_maskz_mov_pd(keep, m));
        }
      }
      if (sums != nullptr) {
        dot = ei::pmadd(m, r, dot);
        m2 = ei::pmadd(m, m, m2);
        r2 = ei::pmadd(r, r, r2);
      }
    }
    if (sums != nullptr) {
      sums->dot += ei::predux(dot);
      sums->modified_norm2 += ei::predux(m2);
      sums->regular_norm2 += ei::predux(r2);
    }
  }
#endif
  // A loop per case: GCC 12 vectorises these (the loops of a build without AVX-512), not one
  // loop testing all three cases inside (`combine` of 13,004 floats in an SSE2 build, the
  // count unused: 3.2 µs in a loop of its own, 12.8 in the shared one).
  if (sums != nullptr) {
    for (; i < n; ++i) {
      const Scalar m = modified[i];
      const Scalar r = regular[i];
      const bool keep = signs_agree(m, r);
      agreeing += keep ? 1 : 0;
      if (combined != nullptr) combined[i] = keep ? m : Scalar(0);
      sums->dot += m * r;
      sums->modified_norm2 += m * m;
      sums->regular_norm2 += r * r;
    }
  } else if (combined != nullptr) {
    for (; i < n; ++i) {
      const Scalar m = modified[i];
      const bool keep = signs_agree(m, regular[i]);
      combined[i] = keep ? m : Scalar(0);
      agreeing += keep ? 1 : 0;
    }
  } else {
    for (; i < n; ++i) agreeing += signs_agree(modified[i], regular[i]) ? 1 : 0;
  }
  return agreeing;
}

/// Throws `InvalidArgument` naming `caller` unless g_M and g_R have the same size.
template <std::floating_point Scalar>
void require_same_size(const Vector<Scalar>& g_modified, const Vector<Scalar>& g_regular,
                       const char* caller) {
  require(g_modified.size() == g_regular.size(), caller, ": g_R size = ", g_regular.size(),
          ", expected the g_M size ", g_modified.size());
}

/// agreeing / n, and 1 for n = 0 (nothing disagrees).
template <std::floating_point Scalar>
[[nodiscard]] Scalar agreement_fraction(Index agreeing, Index n) {
  return n == 0 ? Scalar(1) : static_cast<Scalar>(agreeing) / static_cast<Scalar>(n);
}

}  // namespace detail

/// Fraction of the n components of g_M (size n) and g_R (size n) whose signs agree (see the
/// file comment): the share of g_M that the combined update keeps; 1 for n = 0. Throws
/// `InvalidArgument` on a size mismatch.
template <std::floating_point Scalar>
[[nodiscard]] Scalar sign_agreement(const Vector<Scalar>& g_modified,
                                    const Vector<Scalar>& g_regular) {
  detail::require_same_size(g_modified, g_regular, "sign_agreement");
  const Index agreeing = detail::agreement_pass<Scalar>(g_modified.data(), g_regular.data(),
                                                        g_modified.size(), nullptr, nullptr);
  return detail::agreement_fraction<Scalar>(agreeing, g_modified.size());
}

}  // namespace sbptt
