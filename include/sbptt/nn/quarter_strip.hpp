#pragma once
/// \file dW += D diag(s) Xᵀ (outer_product.hpp) when its rows are a quarter of a register:
/// float 4 of 16 lanes, double 2 of 8 (a first layer on the cart pole's 4 states).
///
/// The panel kernel gives such a panel a register per row: each multiply-add fills a quarter
/// of its lanes and needs a broadcast of its own. Here one register holds the quarters of 4
/// rows (row i + r in lanes r·w … r·w + w − 1, w the quarter's width). X's quarter of a
/// sample is broadcast to the 4 places once per call; d_ik … d_{i+3,k} come in by one load
/// and are spread over their rows' lanes by one permute; the rows' quarters go in and out as
/// 128-bit pieces. This once took the 4 columns after 96 of a 100 × 100 × 8 product too
/// (704–741 ns → 664–672, float, docs/benchmark-runs.md, twentieth run); on Zen 4 that quarter
/// now goes faster in the panel kernel's blocks at quarter width, where it shares their
/// broadcasts (docs/benchmark-runs-zen4.md, thirty-eighth run).
///
/// Each entry is still ((dW_ij + d_i0 x'_j0) + d_i1 x'_j1) + … in sample order with fused
/// multiply-adds, x' = s·x rounded: the panel kernel's order, so the results are the same bit
/// for bit. Compiled where Eigen vectorizes with AVX-512, for float and double.
#include <type_traits>

#include <Eigen/Core>

#include "sbptt/core/first_lanes.hpp"
#include "sbptt/core/types.hpp"
#include "sbptt/core/unroll.hpp"

#if defined(EIGEN_VECTORIZE_AVX512)
#include <immintrin.h>

namespace sbptt::detail {

template <class Scalar>
class QuarterStrip {
public:
  using Packet = FullPacket<Scalar>;
  static constexpr Index kLanes = Eigen::internal::unpacket_traits<Packet>::size;
  /// Entries of a row in the strip.
  static constexpr Index kWidth = kLanes / 4;

  /// dW's columns first … first + kWidth − 1 (the last of its `cols`) += D diag(s) Xᵀ over
  /// `Samples` samples; D is rows × Samples with leading dimension `rows`, X cols × Samples.
  template <int Samples>
  static void add(Scalar* dw, Index rows, Index cols, const Scalar* d, const Scalar* x,
                  const Scalar* scale, Index first) {
    Packet xs[Samples];
    SBPTT_UNROLL
    for (int k = 0; k < Samples; ++k) {
      xs[k] = from_bits(_mm512_broadcast_f32x4(quarter(x + k * cols + first)));
      if (scale != nullptr)
        xs[k] = Eigen::internal::pmul(xs[k], Eigen::internal::pset1<Packet>(scale[k]));
    }
    Index i = 0;
    for (; i + kRowsPerRegister <= rows; i += kRowsPerRegister)
      add_rows<Samples>(dw + i * cols + first, cols, d + i, rows, xs, kRowsPerRegister);
    if (i < rows) add_rows<Samples>(dw + i * cols + first, cols, d + i, rows, xs, rows - i);
  }

private:
  static constexpr int kRowsPerRegister = 4;

  /// Rows 0 … count − 1 (count ≤ 4) of the strip at `w`: only their quarters and their
  /// entries of D are read, only their quarters written.
  template <int Samples>
  EIGEN_ALWAYS_INLINE static void add_rows(Scalar* w, Index ldw, const Scalar* d, Index ldd,
                                           const Packet (&xs)[Samples], Index count) {
    __m512 bits = _mm512_setzero_ps();
    static_for<kRowsPerRegister>([&](auto r) SBPTT_ALWAYS_INLINE {
      constexpr int row = decltype(r)::value;
      if (row < count) bits = _mm512_insertf32x4(bits, quarter(w + row * ldw), row);
    });
    Packet acc = from_bits(bits);
    SBPTT_UNROLL
    for (int k = 0; k < Samples; ++k)
      acc = Eigen::internal::pmadd(xs[k], spread(first_four(d + k * ldd, count)), acc);
    bits = to_bits(acc);
    static_for<kRowsPerRegister>([&](auto r) SBPTT_ALWAYS_INLINE {
      constexpr int row = decltype(r)::value;
      if (row < count)
        _mm_storeu_ps(reinterpret_cast<float*>(w + row * ldw), _mm512_extractf32x4_ps(bits, row));
    });
  }

  /// d[0 … count − 1] in lanes 0 … count − 1 (count ≤ 4); the other lanes are not used.
  EIGEN_ALWAYS_INLINE static Packet first_four(const Scalar* d, Index count) {
    if (count < kRowsPerRegister) return load_first_lanes(d, count);
    if constexpr (std::is_same_v<Scalar, float>) {
      return _mm512_castps128_ps512(_mm_loadu_ps(d));
    } else {
      return _mm512_castpd256_pd512(_mm256_loadu_pd(d));
    }
  }

  /// Lane r of `v` (r < 4) copied to lanes r·kWidth … r·kWidth + kWidth − 1.
  static Packet spread(const Packet& v) {
    if constexpr (std::is_same_v<Scalar, float>) {
      return _mm512_permutexvar_ps(
          _mm512_set_epi32(3, 3, 3, 3, 2, 2, 2, 2, 1, 1, 1, 1, 0, 0, 0, 0), v);
    } else {
      return _mm512_permutexvar_pd(_mm512_set_epi64(3, 3, 2, 2, 1, 1, 0, 0), v);
    }
  }

  static __m128 quarter(const Scalar* from) {
    return _mm_loadu_ps(reinterpret_cast<const float*>(from));
  }
  static Packet from_bits(__m512 bits) {
    if constexpr (std::is_same_v<Scalar, float>) {
      return bits;
    } else {
      return _mm512_castps_pd(bits);
    }
  }
  static __m512 to_bits(const Packet& value) {
    if constexpr (std::is_same_v<Scalar, float>) {
      return value;
    } else {
      return _mm512_castpd_ps(value);
    }
  }
};

}  // namespace sbptt::detail
#endif
