#pragma once
/// \file dW += D diag(s) Xᵀ (outer_product.hpp) for AVX2 with FMA: 16 registers of 8 floats or 4
/// doubles, no masked lanes.
///
/// AVX-512's scheme (X's block in registers, rows of dW streaming past) needs more registers
/// than AVX2 has. Here the block in registers is dW's: 6 rows × 2 panels of accumulators (12
/// registers), each sample adding a broadcast d_ik times 2 panels of x_k, read where they lie
/// (X's columns are contiguous in j). A row's columns go in 2-panel blocks, then single
/// panels, then a half register, then one at a time, so no load or store reaches past dW's row.
/// Measured on an AMD EPYC (Zen 3, AVX2 + FMA), float, 8 samples, against Eigen's product:
/// 100 × 100 in 2.40 µs against 3.38 (67 against 47 GFLOP/s), 100 × 24 in 0.57–0.59 against
/// 0.90, 100 × 10 in 0.63–0.66 against 0.75, 60 × 180 × 56 in 13.0–13.2 against 19.9–20.1
/// (docs/benchmark-runs-avx2.md). 6 × 2 accumulators ran the 100 × 100 product 1.41–1.42 times
/// as fast as Eigen, 5 × 2 1.34 (4 × 2 1.13 and 3 × 3 1.04 in a first version that copied X).
/// Blocks go row by row (a block of rows through all its columns, then the next) when X, times
/// its scale, fits a buffer on the stack, so that dW, which in the engine is not in L1 (a
/// 100 × 100 float gradient is 40 KiB, L1 32 KiB), is read as 6 sequential streams. With 12
/// dW in turn (as from L2), 8 samples, float, 100 × 100 took
/// 2540–2571 ns against 2764–2854 for the blocks column by column, 4 × 100 158–160 against
/// 216–223, 1 × 100 41–42 against 97–99 (Eigen's product: 37–38), 100 × 24 583–597 against
/// 569–575; in double 100 × 100 5314 against 6336 (docs/benchmark-runs-avx2.md, thirty-first
/// run).
/// Longer sums (a convolution's im2col columns) go column block by column block, a block of X
/// scaled once for all rows, in chunks of kChunk samples (the entries of dW are stored between
/// chunks and reloaded: same bits).
///
/// Every entry is ((dW_ij + d_i0 x'_j0) + d_i1 x'_j1) + … in sample order with fused
/// multiply-adds, x' = s·x rounded (x itself without a scale), as in the AVX-512 kernel.
#include <algorithm>
#include <type_traits>

#include <Eigen/Core>

#include "sbptt/core/fused_multiply_add.hpp"
#include "sbptt/core/types.hpp"
#include "sbptt/core/unroll.hpp"

#if defined(EIGEN_VECTORIZE_AVX2) && defined(EIGEN_VECTORIZE_FMA) && \
    !defined(EIGEN_VECTORIZE_AVX512)
#define SBPTT_OUTER_PRODUCT_AVX2 1

namespace sbptt::detail {

template <class Scalar>
class OuterProductAvx2 {
public:
  /// dW (rows × cols, row-major) += D (rows × n, column-major) diag(s) Xᵀ (X: cols × n,
  /// column-major; s: n entries, or none for s = 1).
  static void run(Scalar* dw, Index rows, Index cols, const Scalar* d, const Scalar* x, Index n,
                  const Scalar* scale) {
    if (n <= kChunk && cols * n <= kRowOrderEntries) {
      in_row_order(dw, rows, cols, d, x, n, scale);
      return;
    }
    for_column_blocks(cols, [&]<class P, int Panels>(Index j) {
      columns<P, Panels>(dw, rows, cols, d, x, n, scale, j);
    });
  }

private:
  using Packet = typename Eigen::internal::packet_traits<Scalar>::type;
  using HalfPacket = typename Eigen::internal::packet_traits<Scalar>::half;
  template <class P>
  static constexpr Index lanes_of = Eigen::internal::unpacket_traits<P>::size;
  static constexpr Index kLanes = lanes_of<Packet>;
  static constexpr Index kHalfLanes = lanes_of<HalfPacket>;
  static constexpr int kPanels = 2;
  static constexpr int kRows = 6;
  // Samples of X scaled at a time in column order: the buffer on the stack stays at 4 KiB
  // (float, 2 panels); the convolution's 8 × 56 im2col columns take 7 chunks. The row order
  // takes sums of up to kChunk samples too.
  static constexpr Index kChunk = 64;
  // Entries of X (scaled) that the row order keeps on the stack: 16 KiB in float; the paper's
  // dense layers at batch 8 take at most 420 × 8.
  static constexpr Index kRowOrderEntries = 4096;

  static void in_row_order(Scalar* dw, Index rows, Index cols, const Scalar* d, const Scalar* x,
                           Index n, const Scalar* scale) {
    alignas(64) Scalar scaled[kRowOrderEntries];
    if (scale != nullptr) {
      scale_samples(scaled, cols, x, cols, scale, n);
      x = scaled;
    }
    for_row_blocks(rows, [&]<int Rows>(Index i) {
      for_column_blocks(cols, [&]<class P, int Panels>(Index j) {
        update_rows<P, Panels, Rows>(dw + i * cols + j, cols, d + i, rows, x + j, cols, n);
      });
    });
  }

  /// visit.template operator()<P, Panels>(j) for each block of a row's columns: 2-panel
  /// blocks, then single panels, then a half register, then one at a time, so that no load or
  /// store reaches past the row.
  template <class Visit>
  EIGEN_ALWAYS_INLINE static void for_column_blocks(Index cols, const Visit& visit) {
    Index j = 0;
    for (; j + kPanels * kLanes <= cols; j += kPanels * kLanes)
      visit.template operator()<Packet, kPanels>(j);
    for (; j + kLanes <= cols; j += kLanes) visit.template operator()<Packet, 1>(j);
    for (; j + kHalfLanes <= cols; j += kHalfLanes) visit.template operator()<HalfPacket, 1>(j);
    for (; j < cols; ++j) visit.template operator()<Scalar, 1>(j);
  }

  /// visit.template operator()<Rows>(i) for blocks of kRows rows, then the rows left one at a
  /// time.
  template <class Visit>
  EIGEN_ALWAYS_INLINE static void for_row_blocks(Index rows, const Visit& visit) {
    Index i = 0;
    for (; i + kRows <= rows; i += kRows) visit.template operator()<kRows>(i);
    for (; i < rows; ++i) visit.template operator()<1>(i);
  }

  /// scaled[k·width + c] = s_k·x[k·ldx + c] (one rounding) for `samples` samples.
  static void scale_samples(Scalar* scaled, Index width, const Scalar* x, Index ldx,
                            const Scalar* scale, Index samples) {
    for (Index k = 0; k < samples; ++k)
      for (Index c = 0; c < width; ++c) scaled[k * width + c] = scale[k] * x[k * ldx + c];
  }

  /// Columns first … first + Panels·(P's lanes) − 1 of every row.
  template <class P, int Panels>
  static void columns(Scalar* dw, Index rows, Index cols, const Scalar* d, const Scalar* x,
                      Index n, const Scalar* scale, Index first) {
    constexpr Index width = Panels * lanes_of<P>;
    alignas(64) Scalar scaled[width * kChunk];
    for (Index k0 = 0; k0 < n; k0 += kChunk) {
      const Index samples = std::min(kChunk, n - k0);
      const Scalar* xk = x + k0 * cols + first;
      Index ldx = cols;
      if (scale != nullptr) {
        scale_samples(scaled, width, xk, cols, scale + k0, samples);
        xk = scaled;
        ldx = width;
      }
      const Scalar* dk = d + k0 * rows;
      for_row_blocks(rows, [&]<int Rows>(Index i) {
        update_rows<P, Panels, Rows>(dw + i * cols + first, cols, dk + i, rows, xk, ldx, samples);
      });
    }
  }

  /// a·b + c rounded once, also for the last columns' scalars (Eigen's scalar `pmadd` is a
  /// product and a sum, which clang does not fuse).
  template <class P>
  EIGEN_ALWAYS_INLINE static P fused_madd(const P& a, const P& b, const P& c) {
    if constexpr (std::is_same_v<P, Scalar>) {
      return fused_multiply_add(a, b, c);
    } else {
      return Eigen::internal::pmadd(a, b, c);
    }
  }

  template <class P, int Panels, int Rows>
  EIGEN_ALWAYS_INLINE static void update_rows(Scalar* dw, Index ldw, const Scalar* d, Index ldd,
                                              const Scalar* x, Index ldx, Index samples) {
    using Eigen::internal::ploadu;
    constexpr Index lanes = lanes_of<P>;
    P acc[Rows][Panels];
    SBPTT_UNROLL
    for (int r = 0; r < Rows; ++r) {
      SBPTT_UNROLL
      for (int p = 0; p < Panels; ++p) acc[r][p] = ploadu<P>(dw + r * ldw + p * lanes);
    }
    for (Index k = 0; k < samples; ++k) {
      P xs[Panels];
      SBPTT_UNROLL
      for (int p = 0; p < Panels; ++p) xs[p] = ploadu<P>(x + k * ldx + p * lanes);
      SBPTT_UNROLL
      for (int r = 0; r < Rows; ++r) {
        const P dr = Eigen::internal::pset1<P>(d[r + k * ldd]);
        SBPTT_UNROLL
        for (int p = 0; p < Panels; ++p) acc[r][p] = fused_madd(xs[p], dr, acc[r][p]);
      }
    }
    SBPTT_UNROLL
    for (int r = 0; r < Rows; ++r) {
      SBPTT_UNROLL
      for (int p = 0; p < Panels; ++p)
        Eigen::internal::pstoreu(dw + r * ldw + p * lanes, acc[r][p]);
    }
  }
};

}  // namespace sbptt::detail
#endif
