#pragma once
/// \file The first `count` lanes of a register from or to memory, by masked loads
/// and stores: a matrix's last panel narrower than a register (the packed and the outer
/// products), or a tile's columns shorter than one (the simulators' lane rows), without
/// reading or writing past its end. Lanes not loaded are 0; memory past the lanes stored is
/// left as it was. And the lower half or quarter of a register as a narrower one, for a panel
/// that fills no more: where a core splits a 512-bit multiply-add in two 256-bit halves (AMD
/// Zen 4), a masked register costs a whole one, half a register half of one. Defined where
/// Eigen vectorizes with AVX-512, for float and double; the first lanes of a register (no
/// narrower parts) also where it vectorizes with AVX2 and not AVX-512: its 256-bit registers
/// have no mask registers, so a vector mask goes there (`vmaskmovps`). Its lanes left out are
/// neither read nor written; Intel guarantees that they do not fault either, AMD leaves it to
/// the implementation, and this code relies on it as Eigen's own masked AVX moves do (the last
/// column of a batch matrix ends at its allocation).
#include <type_traits>

#include <Eigen/Core>

#include "sbptt/core/types.hpp"

#if defined(EIGEN_VECTORIZE_AVX512) || defined(EIGEN_VECTORIZE_AVX2)
#include <immintrin.h>

namespace sbptt::detail {

/// Eigen's widest register of `Scalar`: 16 floats or 8 doubles with AVX-512, 8 or 4 with AVX2.
template <class Scalar>
using FullPacket = typename Eigen::internal::packet_traits<Scalar>::type;

#if defined(EIGEN_VECTORIZE_AVX512)
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

#else  // AVX2
/// The lanes of a 256-bit register of `Scalar`.
template <class Scalar>
inline constexpr auto register_lanes = static_cast<Index>(32 / sizeof(Scalar));

/// All bits set in the 32-bit (float) or 64-bit (double) lanes 0 … count − 1 (0 < count ≤ the
/// register's lanes), none in the others.
template <class Scalar>
EIGEN_ALWAYS_INLINE __m256i first_lanes_mask(Index count) {
  if constexpr (std::is_same_v<Scalar, float>) {
    return _mm256_cmpgt_epi32(_mm256_set1_epi32(static_cast<int>(count)),
                              _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7));
  } else {
    return _mm256_cmpgt_epi64(_mm256_set1_epi64x(count), _mm256_setr_epi64x(0, 1, 2, 3));
  }
}

// A whole register goes by a plain load or store: the masked ones cost more even with every
// lane selected (AMD EPYC without AVX-512: guidance's paired VJP of 8 samples 1312 ns with masks on
// every tile, 1170 with plain moves for the whole ones; docs/benchmark-runs.md, eighty-second
// run).

template <class Scalar>
EIGEN_ALWAYS_INLINE FullPacket<Scalar> load_first_lanes(const Scalar* from, Index count) {
  static_assert(FloatOrDouble<Scalar>);
  if (count == register_lanes<Scalar>) return Eigen::internal::ploadu<FullPacket<Scalar>>(from);
  if constexpr (std::is_same_v<Scalar, float>) {
    return _mm256_maskload_ps(from, first_lanes_mask<Scalar>(count));
  } else {
    return _mm256_maskload_pd(from, first_lanes_mask<Scalar>(count));
  }
}

template <class Scalar>
EIGEN_ALWAYS_INLINE void store_first_lanes(Scalar* to, const FullPacket<Scalar>& value,
                                           Index count) {
  static_assert(FloatOrDouble<Scalar>);
  if (count == register_lanes<Scalar>) return Eigen::internal::pstoreu(to, value);
  if constexpr (std::is_same_v<Scalar, float>) {
    _mm256_maskstore_ps(to, first_lanes_mask<Scalar>(count), value);
  } else {
    _mm256_maskstore_pd(to, first_lanes_mask<Scalar>(count), value);
  }
}
#endif

}  // namespace sbptt::detail
#endif

#if defined(EIGEN_VECTORIZE_AVX512)
namespace sbptt::detail {

/// The register of the lower 1/Fraction of a `FullPacket` (Fraction 2 or 4). Named type by
/// type: a vector type as a template argument loses its attributes (GCC warns).
template <int Fraction, class Scalar>
struct LowerPacketOf;
template <class Scalar>
struct LowerPacketOf<2, Scalar> {
  using Type = typename Eigen::internal::packet_traits<Scalar>::half;
};
template <>
struct LowerPacketOf<4, float> {
  using Type = Eigen::internal::Packet4f;
};
template <>
struct LowerPacketOf<4, double> {
  using Type = Eigen::internal::Packet2d;
};
template <int Fraction, class Scalar>
using LowerPacket = typename LowerPacketOf<Fraction, Scalar>::Type;

/// The lower 1/Fraction of `value`'s lanes as a narrower register, and such a register as the
/// lower lanes of a whole one (the others undefined): casts, no instruction.
template <int Fraction, class Scalar>
EIGEN_ALWAYS_INLINE LowerPacket<Fraction, Scalar> lower_part(const FullPacket<Scalar>& value) {
  if constexpr (std::is_same_v<Scalar, float>) {
    if constexpr (Fraction == 2) return _mm512_castps512_ps256(value);
    if constexpr (Fraction == 4) return _mm512_castps512_ps128(value);
  } else {
    if constexpr (Fraction == 2) return _mm512_castpd512_pd256(value);
    if constexpr (Fraction == 4) return _mm512_castpd512_pd128(value);
  }
}
template <int Fraction, class Scalar>
EIGEN_ALWAYS_INLINE FullPacket<Scalar> from_lower_part(const LowerPacket<Fraction, Scalar>& value) {
  if constexpr (std::is_same_v<Scalar, float>) {
    if constexpr (Fraction == 2) return _mm512_castps256_ps512(value);
    if constexpr (Fraction == 4) return _mm512_castps128_ps512(value);
  } else {
    if constexpr (Fraction == 2) return _mm512_castpd256_pd512(value);
    if constexpr (Fraction == 4) return _mm512_castpd128_pd512(value);
  }
}

/// a·b + c in the lower 1/Fraction of the registers (the other lanes undefined).
template <int Fraction, class Scalar>
EIGEN_ALWAYS_INLINE FullPacket<Scalar> lower_madd(const FullPacket<Scalar>& a,
                                                  const FullPacket<Scalar>& b,
                                                  const FullPacket<Scalar>& c) {
  return from_lower_part<Fraction, Scalar>(
      Eigen::internal::pmadd(lower_part<Fraction, Scalar>(a), lower_part<Fraction, Scalar>(b),
                             lower_part<Fraction, Scalar>(c)));
}

/// The first 1/Fraction of a register's lanes from memory, by a load of that width.
template <int Fraction, class Scalar>
EIGEN_ALWAYS_INLINE FullPacket<Scalar> load_lower_part(const Scalar* from) {
  return from_lower_part<Fraction, Scalar>(
      Eigen::internal::ploadu<LowerPacket<Fraction, Scalar>>(from));
}

}  // namespace sbptt::detail
#endif
