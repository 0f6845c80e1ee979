#pragma once
/// \file Samples side by side in SIMD lanes, for a simulator's batched step: one row of a
/// batch matrix (a sample per column) over a block of kLanes columns, held as one Eigen array,
/// so that each arithmetic expression on it is one instruction over the whole block instead of
/// one scalar operation per sample.
///
/// A block is 64 bytes of each row (16 floats or 8 doubles, one AVX-512 register; narrower
/// instruction sets split it). A batch's last, partial block is padded with 0, so that every
/// block runs the same instructions: a sample's result does not depend on its place in the
/// batch or on the batch's size, as long as the arithmetic on a lane reads only that lane.
///
/// A batch matrix holds a sample's rows together (column-major), a block of lanes a row's
/// samples together: moving a whole block in or out (`load_rows`, `store_rows`) transposes it.
/// On AVX-512 that goes by tiles of kLanes × kLanes, a column of the tile a register,
/// transposed in registers (guidance's `vjp_batch` moves 52 rows in and 28 out per block:
/// entry by entry, about 0.15–0.2 ns an entry; docs/benchmark-runs.md, eighteenth run).
#include <algorithm>
#include <type_traits>

#include <Eigen/Core>

#include "sbptt/core/first_lanes.hpp"
#include "sbptt/core/types.hpp"
#include "sbptt/core/unroll.hpp"

namespace sbptt::detail {

template <class Scalar>
struct LaneRows {
  static constexpr int kLanes = static_cast<int>(64 / sizeof(Scalar));
  using Values = Eigen::Array<Scalar, kLanes, 1>;  ///< lane l: sample first + l of the block

  /// Samples in the block starting at column `first` of a batch of `batch`.
  [[nodiscard]] static int count(Index batch, Index first) {
    return static_cast<int>(std::min<Index>(kLanes, batch - first));
  }

  /// Row `row` of columns first … first + count − 1 of `m`; the lanes past `count` are 0.
  [[nodiscard]] static Values load(const Matrix<Scalar>& m, Index row, Index first, int count) {
    Values v;
    for (int l = 0; l < kLanes; ++l) v(l) = l < count ? m(row, first + l) : Scalar(0);
    return v;
  }

  /// The first `count` lanes of `v` into row `row`, columns first … first + count − 1 of `m`.
  static void store(const Values& v, Matrix<Scalar>& m, Index row, Index first, int count) {
    for (int l = 0; l < count; ++l) m(row, first + l) = v(l);
  }

  /// Every row of columns first … first + count − 1 of `m` into `rows` (m.rows() arrays), as
  /// `load` row by row.
  EIGEN_ALWAYS_INLINE static void load_rows(const Matrix<Scalar>& m, Index first, int count,
                                            Values* rows) {
#if defined(EIGEN_VECTORIZE_AVX512)
    if constexpr (kTransposeInRegisters) {
      return load_tiles(m, first, count, rows);
    }
#endif
    for (Index r = 0; r < m.rows(); ++r) rows[r] = load(m, r, first, count);
  }

  /// The first `count` lanes of `rows` (m.rows() arrays) into columns first … first + count − 1
  /// of `m`, as `store` row by row.
  EIGEN_ALWAYS_INLINE static void store_rows(const Values* rows, Index first, int count,
                                             Matrix<Scalar>& m) {
#if defined(EIGEN_VECTORIZE_AVX512)
    if constexpr (kTransposeInRegisters) {
      return store_tiles(rows, first, count, m);
    }
#endif
    for (Index r = 0; r < m.rows(); ++r) store(rows[r], m, r, first, count);
  }

private:
#if defined(EIGEN_VECTORIZE_AVX512)
  static constexpr bool kTransposeInRegisters = FloatOrDouble<Scalar>;
  using Packet = typename Eigen::internal::packet_traits<Scalar>::type;
  static Packet zero() { return Eigen::internal::pset1<Packet>(Scalar(0)); }

  EIGEN_ALWAYS_INLINE static void load_tiles(const Matrix<Scalar>& m, Index first, int count,
                                             Values* rows) {
    for (Index top = 0; top < m.rows(); top += kLanes) {
      const Index height = std::min<Index>(kLanes, m.rows() - top);
      Packet tile[kLanes];
      SBPTT_UNROLL
      for (int l = 0; l < kLanes; ++l)
        tile[l] = l < count ? load_first_lanes(&m(top, first + l), height) : zero();
      transpose(tile);
      SBPTT_UNROLL
      for (Index i = 0; i < height; ++i) Eigen::internal::pstoreu(rows[top + i].data(), tile[i]);
    }
  }

  EIGEN_ALWAYS_INLINE static void store_tiles(const Values* rows, Index first, int count,
                                              Matrix<Scalar>& m) {
    for (Index top = 0; top < m.rows(); top += kLanes) {
      const Index height = std::min<Index>(kLanes, m.rows() - top);
      Packet tile[kLanes];
      SBPTT_UNROLL
      for (Index i = 0; i < kLanes; ++i)
        tile[i] = i < height ? Eigen::internal::ploadu<Packet>(rows[top + i].data()) : zero();
      transpose(tile);
      SBPTT_UNROLL
      for (int l = 0; l < count; ++l) store_first_lanes(&m(top, first + l), tile[l], height);
    }
  }

  // The interleaves are the masked forms with every lane selected, which run as fast: GCC 12
  // gives the unmasked ones an undefined register to merge into, and its -Wall reports that as
  // uninitialized in every function they are inlined into (GCC bug 105593).
  // Entries (32-bit for __m512, 64-bit for __m512d) of a and b alternating, from the low
  // (High: high) half of each 128-bit quarter.
  template <bool High>
  static __m512 interleave(__m512 a, __m512 b) {
    return High ? _mm512_mask_unpackhi_ps(a, 0xFFFF, a, b)
                : _mm512_mask_unpacklo_ps(a, 0xFFFF, a, b);
  }
  template <bool High>
  static __m512d interleave(__m512d a, __m512d b) {
    return High ? _mm512_mask_unpackhi_pd(a, 0xFF, a, b) : _mm512_mask_unpacklo_pd(a, 0xFF, a, b);
  }
  /// The first stage of either transpose: registers 2k and 2k + 1 interleaved into t.
  template <int Count, class Register>
  EIGEN_ALWAYS_INLINE static void interleave_neighbours(const Register* r, Register* t) {
    SBPTT_UNROLL
    for (int i = 0; i < Count; i += 2) {
      t[i] = interleave<false>(r[i], r[i + 1]);
      t[i + 1] = interleave<true>(r[i], r[i + 1]);
    }
  }
  /// 128-bit quarters 0 and 2 (Odd: 1 and 3) of a, then of b.
  template <bool Odd>
  static __m512 quarters(__m512 a, __m512 b) {
    return _mm512_mask_shuffle_f32x4(a, 0xFFFF, a, b, Odd ? 0xdd : 0x88);
  }
  template <bool Odd>
  static __m512d quarters(__m512d a, __m512d b) {
    return _mm512_mask_shuffle_f64x2(a, 0xFF, a, b, Odd ? 0xdd : 0x88);
  }

  /// Register l's lane i to register i's lane l: 32-bit, 64-bit, then twice 128-bit
  /// interleaves for 16 floats; 64-bit, then twice 128-bit for 8 doubles. (Eigen's
  /// `ptranspose` of these blocks goes through 256-bit halves: extracts, 256-bit permutes and
  /// inserts on top of the same interleaves.)
  EIGEN_ALWAYS_INLINE static void transpose(Packet* r) {
    if constexpr (std::is_same_v<Scalar, float>) {
      __m512 t[16];
      interleave_neighbours<16>(r, t);
      SBPTT_UNROLL
      for (int i = 0; i < 16; i += 4) {
        const __m512d a = _mm512_castps_pd(t[i]), b = _mm512_castps_pd(t[i + 1]);
        const __m512d c = _mm512_castps_pd(t[i + 2]), d = _mm512_castps_pd(t[i + 3]);
        r[i] = _mm512_castpd_ps(interleave<false>(a, c));
        r[i + 1] = _mm512_castpd_ps(interleave<true>(a, c));
        r[i + 2] = _mm512_castpd_ps(interleave<false>(b, d));
        r[i + 3] = _mm512_castpd_ps(interleave<true>(b, d));
      }
      // r[4q + j] holds entry j, 4 + j, 8 + j, 12 + j (a 128-bit quarter each) of registers
      // 4q … 4q + 3.
      SBPTT_UNROLL
      for (int j = 0; j < 4; ++j) {
        t[j] = quarters<false>(r[j], r[4 + j]);     // entries j, 8 + j
        t[4 + j] = quarters<true>(r[j], r[4 + j]);  // entries 4 + j, 12 + j
        t[8 + j] = quarters<false>(r[8 + j], r[12 + j]);
        t[12 + j] = quarters<true>(r[8 + j], r[12 + j]);
      }
      SBPTT_UNROLL
      for (int j = 0; j < 4; ++j) {
        r[j] = quarters<false>(t[j], t[8 + j]);
        r[8 + j] = quarters<true>(t[j], t[8 + j]);
        r[4 + j] = quarters<false>(t[4 + j], t[12 + j]);
        r[12 + j] = quarters<true>(t[4 + j], t[12 + j]);
      }
    } else {
      static_assert(std::is_same_v<Scalar, double>);
      __m512d t[8];
      interleave_neighbours<8>(r, t);
      // t[2q] holds entries 0, 2, 4, 6 of registers 2q, 2q + 1; t[2q + 1] entries 1, 3, 5, 7.
      SBPTT_UNROLL
      for (int q = 0; q < 8; q += 4) {
        r[q] = quarters<false>(t[q], t[q + 2]);          // entries 0, 4
        r[q + 1] = quarters<false>(t[q + 1], t[q + 3]);  // 1, 5
        r[q + 2] = quarters<true>(t[q], t[q + 2]);       // 2, 6
        r[q + 3] = quarters<true>(t[q + 1], t[q + 3]);   // 3, 7
      }
      SBPTT_UNROLL
      for (int j = 0; j < 4; ++j) {
        t[j] = quarters<false>(r[j], r[4 + j]);
        t[4 + j] = quarters<true>(r[j], r[4 + j]);
      }
      std::copy(t, t + 8, r);
    }
  }
#endif
};

}  // namespace sbptt::detail
