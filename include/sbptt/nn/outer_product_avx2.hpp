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
/// A single row, an output layer's, is slower than Eigen's product (1 × 100: 62–92 against 37–38
/// ns, 1 × 420: 372 against 124) but kept, so that every entry has the order below; a few tenths
/// of a percent of the cart pole's and quantum control's epochs.
/// A pass over the rows of a column block adds up to kChunk samples, from up to kMaxPieces
/// pieces (terms, the steps of a sweep, or parts of a longer term); dW's entries are stored
/// between passes and reloaded: same bits. A scale s multiplies a piece's block of X once for
/// all rows, into a buffer on the stack.
///
/// Every entry is ((dW_ij + d_i0 x'_j0) + d_i1 x'_j1) + … in sample order with fused
/// multiply-adds, x' = s·x rounded (x itself without a scale), as in the AVX-512 kernel.
#include <algorithm>
#include <span>
#include <type_traits>

#include <Eigen/Core>

#include "sbptt/core/fused_multiply_add.hpp"
#include "sbptt/core/types.hpp"
#include "sbptt/core/unroll.hpp"
#include "sbptt/nn/outer_product_term.hpp"

#if defined(EIGEN_VECTORIZE_AVX2) && defined(EIGEN_VECTORIZE_FMA) && \
    !defined(EIGEN_VECTORIZE_AVX512)
#define SBPTT_OUTER_PRODUCT_AVX2 1

namespace sbptt::detail {

template <class Scalar>
class OuterProductAvx2 {
public:
  /// dW (rows × cols, row-major) += Σ_t D_t diag(s_t) X_tᵀ over `terms` in their order
  /// (outer_product.hpp, `OuterProductTerm`).
  static void run(Scalar* dw, Index rows, Index cols,
                  std::span<const OuterProductTerm<Scalar>> terms) {
    Index j = 0;
    for (; j + kPanels * kLanes <= cols; j += kPanels * kLanes)
      columns<Packet, kPanels>(dw, rows, cols, terms, j);
    for (; j + kLanes <= cols; j += kLanes) columns<Packet, 1>(dw, rows, cols, terms, j);
    for (; j + kHalfLanes <= cols; j += kHalfLanes)
      columns<HalfPacket, 1>(dw, rows, cols, terms, j);
    for (; j < cols; ++j) columns<Scalar, 1>(dw, rows, cols, terms, j);
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
  // Samples a pass takes: the scaled buffer on the stack stays at 4 KiB (float, 2 panels), and
  // the block of X the rows share stays in L1 (60 × 180 × 448, unscaled, float: 142 µs in one
  // pass against 114 in passes of 64). The paper's batches (8, and 8 × 56 im2col columns)
  // take 1 and 7 passes a step.
  static constexpr Index kChunk = 64;

  /// Samples of one term that a pass over dW's rows adds: D's columns from `d` (leading
  /// dimension: dW's rows), X's from `x` (leading dimension `ldx`).
  struct Piece {
    const Scalar* d;
    const Scalar* x;
    Index ldx;
    Index samples;
  };
  // Pieces a pass takes: a pass loads and stores dW's block once for all of them, which is
  // what the terms of several steps gain (100 × 100 × 8 a step, float: 2514 ns a step alone,
  // 2093–2159 two steps a call; docs/benchmark-runs-avx2.md).
  static constexpr int kMaxPieces = 4;

  /// Columns first … first + Panels·(P's lanes) − 1 of every row, in passes of up to
  /// kMaxPieces pieces and kChunk scaled samples.
  template <class P, int Panels>
  static void columns(Scalar* dw, Index rows, Index cols,
                      std::span<const OuterProductTerm<Scalar>> terms, Index first) {
    constexpr Index width = Panels * lanes_of<P>;
    alignas(64) Scalar scaled[width * kChunk];
    Piece pieces[kMaxPieces];
    int count = 0;
    Index taken = 0;  // samples in the pass
    auto pass = [&] {
      if (count == 1) {
        rows_of<P, Panels>(dw + first, rows, cols, &pieces[0], 1, std::true_type{});
      } else {
        rows_of<P, Panels>(dw + first, rows, cols, pieces, count, std::false_type{});
      }
      count = 0;
      taken = 0;
    };
    for (const OuterProductTerm<Scalar>& term : terms) {
      for (Index k0 = 0; k0 < term.n;) {
        if (count == kMaxPieces || taken == kChunk) pass();
        const Index samples = std::min(term.n - k0, kChunk - taken);
        const Scalar* xk = term.x + k0 * cols + first;
        Index ldx = cols;
        if (term.scale != nullptr) {
          Scalar* to = scaled + taken * width;
          for (Index k = 0; k < samples; ++k)
            for (Index c = 0; c < width; ++c)
              to[k * width + c] = term.scale[k0 + k] * xk[k * cols + c];
          xk = to;
          ldx = width;
        }
        pieces[count++] = Piece{term.d + k0 * rows, xk, ldx, samples};
        taken += samples;
        k0 += samples;
      }
    }
    if (count > 0) pass();
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

  /// Every row of dW's block at `dw` (leading dimension cols) through `pieces`; `single`
  /// (one piece) lets the compiler keep the piece in registers across the rows: through the
  /// general loop, 4 × 100 × 8 took 347 ns against 171 before pieces.
  template <class P, int Panels, class Single>
  static void rows_of(Scalar* dw, Index rows, Index cols, const Piece* pieces, int count,
                      Single single) {
    Index i = 0;
    for (; i + kRows <= rows; i += kRows)
      update_rows<P, Panels, kRows>(dw + i * cols, cols, i, rows, pieces, count, single);
    for (; i < rows; ++i)
      update_rows<P, Panels, 1>(dw + i * cols, cols, i, rows, pieces, count, single);
  }

  /// acc += the samples of `piece` for rows `row` … `row` + Rows − 1.
  template <class P, int Panels, int Rows>
  EIGEN_ALWAYS_INLINE static void add_piece(P (&acc)[Rows][Panels], Piece piece,
                                            Index row, Index ldd) {
    constexpr Index lanes = lanes_of<P>;
    const Scalar* d = piece.d + row;
    for (Index k = 0; k < piece.samples; ++k) {
      P xs[Panels];
      SBPTT_UNROLL
      for (int p = 0; p < Panels; ++p)
        xs[p] = Eigen::internal::ploadu<P>(piece.x + k * piece.ldx + p * lanes);
      SBPTT_UNROLL
      for (int r = 0; r < Rows; ++r) {
        const P dr = Eigen::internal::pset1<P>(d[r + k * ldd]);
        SBPTT_UNROLL
        for (int p = 0; p < Panels; ++p) acc[r][p] = fused_madd(xs[p], dr, acc[r][p]);
      }
    }
  }

  /// Rows `row` … `row` + Rows − 1 of the block at `dw` (leading dimension ldw), D's leading
  /// dimension ldd: every piece's samples in order.
  template <class P, int Panels, int Rows, class Single>
  EIGEN_ALWAYS_INLINE static void update_rows(Scalar* dw, Index ldw, Index row, Index ldd,
                                              const Piece* pieces, int count, Single) {
    using Eigen::internal::ploadu;
    constexpr Index lanes = lanes_of<P>;
    P acc[Rows][Panels];
    SBPTT_UNROLL
    for (int r = 0; r < Rows; ++r) {
      SBPTT_UNROLL
      for (int p = 0; p < Panels; ++p) acc[r][p] = ploadu<P>(dw + r * ldw + p * lanes);
    }
    if constexpr (Single::value) {
      add_piece<P, Panels, Rows>(acc, pieces[0], row, ldd);
    } else {
      for (int q = 0; q < count; ++q) add_piece<P, Panels, Rows>(acc, pieces[q], row, ldd);
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
