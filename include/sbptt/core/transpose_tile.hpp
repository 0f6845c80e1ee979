#pragma once
/// \file A square tile of a register's lanes transposed in registers: register l's lane i to
/// register i's lane l (AVX-512: 16 × 16 floats or 8 × 8 doubles; AVX2: 8 × 8 or 4 × 4).
/// Moving a batch matrix in and out of a simulator's lanes (sim/lane_rows.hpp) and, with
/// AVX-512, packing a weight matrix's panels (nn/packed_product.hpp) turn rows into columns
/// this way, instead of entry by entry. Defined where Eigen vectorizes with AVX-512 or AVX2,
/// for float and double.
#include <algorithm>
#include <type_traits>

#include <Eigen/Core>

#include "sbptt/core/first_lanes.hpp"
#include "sbptt/core/unroll.hpp"

#if defined(EIGEN_VECTORIZE_AVX512)
#include <immintrin.h>

namespace sbptt::detail {
namespace tile_steps {

// The interleaves are the masked forms with every lane selected, which run as fast: GCC 12
// gives the unmasked ones an undefined register to merge into, and its -Wall reports that as
// uninitialized in every function they are inlined into (GCC bug 105593).
// Entries (32-bit for __m512, 64-bit for __m512d) of a and b alternating, from the low
// (High: high) half of each 128-bit quarter.
template <bool High>
EIGEN_ALWAYS_INLINE __m512 interleave(__m512 a, __m512 b) {
  return High ? _mm512_mask_unpackhi_ps(a, 0xFFFF, a, b)
              : _mm512_mask_unpacklo_ps(a, 0xFFFF, a, b);
}
template <bool High>
EIGEN_ALWAYS_INLINE __m512d interleave(__m512d a, __m512d b) {
  return High ? _mm512_mask_unpackhi_pd(a, 0xFF, a, b) : _mm512_mask_unpacklo_pd(a, 0xFF, a, b);
}
/// The first stage of either transpose: registers 2k and 2k + 1 interleaved into t.
template <int Count, class Register>
EIGEN_ALWAYS_INLINE void interleave_neighbours(const Register* r, Register* t) {
  SBPTT_UNROLL
  for (int i = 0; i < Count; i += 2) {
    t[i] = interleave<false>(r[i], r[i + 1]);
    t[i + 1] = interleave<true>(r[i], r[i + 1]);
  }
}
/// 128-bit quarters 0 and 2 (Odd: 1 and 3) of a, then of b.
template <bool Odd>
EIGEN_ALWAYS_INLINE __m512 quarters(__m512 a, __m512 b) {
  return _mm512_mask_shuffle_f32x4(a, 0xFFFF, a, b, Odd ? 0xdd : 0x88);
}
template <bool Odd>
EIGEN_ALWAYS_INLINE __m512d quarters(__m512d a, __m512d b) {
  return _mm512_mask_shuffle_f64x2(a, 0xFF, a, b, Odd ? 0xdd : 0x88);
}

}  // namespace tile_steps

/// Register l's lane i to register i's lane l: 32-bit, 64-bit, then twice 128-bit
/// interleaves for 16 floats; 64-bit, then twice 128-bit for 8 doubles. (Eigen's
/// `ptranspose` of these blocks goes through 256-bit halves: extracts, 256-bit permutes and
/// inserts on top of the same interleaves.)
template <class Scalar>
EIGEN_ALWAYS_INLINE void transpose_tile(FullPacket<Scalar>* r) {
  if constexpr (std::is_same_v<Scalar, float>) {
    __m512 t[16];
    tile_steps::interleave_neighbours<16>(r, t);
    SBPTT_UNROLL
    for (int i = 0; i < 16; i += 4) {
      const __m512d a = _mm512_castps_pd(t[i]), b = _mm512_castps_pd(t[i + 1]);
      const __m512d c = _mm512_castps_pd(t[i + 2]), d = _mm512_castps_pd(t[i + 3]);
      r[i] = _mm512_castpd_ps(tile_steps::interleave<false>(a, c));
      r[i + 1] = _mm512_castpd_ps(tile_steps::interleave<true>(a, c));
      r[i + 2] = _mm512_castpd_ps(tile_steps::interleave<false>(b, d));
      r[i + 3] = _mm512_castpd_ps(tile_steps::interleave<true>(b, d));
    }
    // r[4q + j] holds entry j, 4 + j, 8 + j, 12 + j (a 128-bit quarter each) of registers
    // 4q … 4q + 3.
    SBPTT_UNROLL
    for (int j = 0; j < 4; ++j) {
      t[j] = tile_steps::quarters<false>(r[j], r[4 + j]);     // entries j, 8 + j
      t[4 + j] = tile_steps::quarters<true>(r[j], r[4 + j]);  // entries 4 + j, 12 + j
      t[8 + j] = tile_steps::quarters<false>(r[8 + j], r[12 + j]);
      t[12 + j] = tile_steps::quarters<true>(r[8 + j], r[12 + j]);
    }
    SBPTT_UNROLL
    for (int j = 0; j < 4; ++j) {
      r[j] = tile_steps::quarters<false>(t[j], t[8 + j]);
      r[8 + j] = tile_steps::quarters<true>(t[j], t[8 + j]);
      r[4 + j] = tile_steps::quarters<false>(t[4 + j], t[12 + j]);
      r[12 + j] = tile_steps::quarters<true>(t[4 + j], t[12 + j]);
    }
  } else {
    static_assert(std::is_same_v<Scalar, double>);
    __m512d t[8];
    tile_steps::interleave_neighbours<8>(r, t);
    // t[2q] holds entries 0, 2, 4, 6 of registers 2q, 2q + 1; t[2q + 1] entries 1, 3, 5, 7.
    SBPTT_UNROLL
    for (int q = 0; q < 8; q += 4) {
      r[q] = tile_steps::quarters<false>(t[q], t[q + 2]);          // entries 0, 4
      r[q + 1] = tile_steps::quarters<false>(t[q + 1], t[q + 3]);  // 1, 5
      r[q + 2] = tile_steps::quarters<true>(t[q], t[q + 2]);       // 2, 6
      r[q + 3] = tile_steps::quarters<true>(t[q + 1], t[q + 3]);   // 3, 7
    }
    SBPTT_UNROLL
    for (int j = 0; j < 4; ++j) {
      t[j] = tile_steps::quarters<false>(r[j], r[4 + j]);
      t[4 + j] = tile_steps::quarters<true>(r[j], r[4 + j]);
    }
    std::copy(t, t + 8, r);
  }
}

}  // namespace sbptt::detail

#elif defined(EIGEN_VECTORIZE_AVX2)
#include <immintrin.h>

namespace sbptt::detail {

/// Register l's lane i to register i's lane l: 32-bit (64-bit for doubles) interleaves of
/// neighbouring registers, for floats a 64-bit shuffle of those, then a 128-bit permute: the
/// steps of Eigen's `ptranspose`, which takes a `PacketBlock` instead of the callers' array
/// and whose vector template argument GCC 12 warns about (-Wignored-attributes) in our headers.
template <class Scalar>
EIGEN_ALWAYS_INLINE void transpose_tile(FullPacket<Scalar>* r) {
  if constexpr (std::is_same_v<Scalar, float>) {
    __m256 t[8];
    SBPTT_UNROLL
    for (int i = 0; i < 8; i += 2) {
      t[i] = _mm256_unpacklo_ps(r[i], r[i + 1]);
      t[i + 1] = _mm256_unpackhi_ps(r[i], r[i + 1]);
    }
    // t[i] holds entries 0, 1 of registers i and i + 1 alternating (4, 5 in its upper 128
    // bits), t[i + 1] entries 2, 3 (6, 7).
    __m256 u[8];
    SBPTT_UNROLL
    for (int i = 0; i < 8; i += 4) {
      u[i] = _mm256_shuffle_ps(t[i], t[i + 2], _MM_SHUFFLE(1, 0, 1, 0));
      u[i + 1] = _mm256_shuffle_ps(t[i], t[i + 2], _MM_SHUFFLE(3, 2, 3, 2));
      u[i + 2] = _mm256_shuffle_ps(t[i + 1], t[i + 3], _MM_SHUFFLE(1, 0, 1, 0));
      u[i + 3] = _mm256_shuffle_ps(t[i + 1], t[i + 3], _MM_SHUFFLE(3, 2, 3, 2));
    }
    // u[j] (u[4 + j]) holds entry j and 4 + j of registers 0–3 (4–7).
    SBPTT_UNROLL
    for (int j = 0; j < 4; ++j) {
      r[j] = _mm256_permute2f128_ps(u[j], u[4 + j], 0x20);
      r[4 + j] = _mm256_permute2f128_ps(u[j], u[4 + j], 0x31);
    }
  } else {
    static_assert(std::is_same_v<Scalar, double>);
    const __m256d t0 = _mm256_unpacklo_pd(r[0], r[1]), t1 = _mm256_unpackhi_pd(r[0], r[1]);
    const __m256d t2 = _mm256_unpacklo_pd(r[2], r[3]), t3 = _mm256_unpackhi_pd(r[2], r[3]);
    r[0] = _mm256_permute2f128_pd(t0, t2, 0x20);
    r[1] = _mm256_permute2f128_pd(t1, t3, 0x20);
    r[2] = _mm256_permute2f128_pd(t0, t2, 0x31);
    r[3] = _mm256_permute2f128_pd(t1, t3, 0x31);
  }
}

}  // namespace sbptt::detail

#endif  // EIGEN_VECTORIZE_AVX512, EIGEN_VECTORIZE_AVX2
