#pragma once
/// \file The first `count` lanes of an AVX-512 register from or to memory, by masked loads
/// and stores: a matrix's last panel narrower than a register (the packed and the outer
/// products), or a tile's columns shorter than one (the simulators' lane rows), without
/// reading or writing past its end. Lanes not loaded are 0; memory past the lanes stored is
/// left as it was. Defined only where Eigen vectorizes with AVX-512, for float and double.
#include <type_traits>

#include <Eigen/Core>

#include "sbptt/core/types.hpp"

#if defined(EIGEN_VECTORIZE_AVX512)
#include <immintrin.h>

namespace sbptt::detail {

/// Eigen's AVX-512 register of `Scalar` (16 floats or 8 doubles).
template <class Scalar>
using FullPacket = typename Eigen::internal::packet_traits<Scalar>::type;

/// The mask of lanes 0 … count − 1 (0 < count ≤ the register's lanes).
template <class Mask>
EIGEN_ALWAYS_INLINE Mask first_lanes_mask(Index count) {
  return static_cast<Mask>((1U << static_cast<unsigned>(count)) - 1U);
}

template <class Scalar>
EIGEN_ALWAYS_INLINE FullPacket<Scalar> load_first_lanes(const Scalar* from, Index count) {
  static_assert(FloatOrDouble<Scalar>);
  if constexpr (std::is_same_v<Scalar, float>) {
    return _mm512_maskz_loadu_ps(first_lanes_mask<__mmask16>(count), from);
  } else {
    return _mm512_maskz_loadu_pd(first_lanes_mask<__mmask8>(count), from);
  }
}

template <class Scalar>
EIGEN_ALWAYS_INLINE void store_first_lanes(Scalar* to, const FullPacket<Scalar>& value,
                                           Index count) {
  static_assert(FloatOrDouble<Scalar>);
  if constexpr (std::is_same_v<Scalar, float>) {
    _mm512_mask_storeu_ps(to, first_lanes_mask<__mmask16>(count), value);
  } else {
    _mm512_mask_storeu_pd(to, first_lanes_mask<__mmask8>(count), value);
  }
}

}  // namespace sbptt::detail
#endif
