#pragma once
/// \file Y = A X (+ b) with A packed once and reused: the products of a network layer.
///
/// A rollout multiplies the same weight by a small batch (8 samples in the paper) at every one
/// of its steps. A general matrix product packs its left operand on every call, and at 8
/// columns that packing and the zeroing of the destination cost as much as the multiply-adds
/// (docs/benchmark-runs.md, second run). Packing the weight once per parameter update and
/// keeping it turns each step's product into the loop below, which runs at the core's
/// multiply-add peak.
///
/// Layout: A (rows × cols) is cut into panels of `kLanes` rows (one SIMD register); a panel
/// stores its columns one after another, each as kLanes contiguous scalars, and the last
/// panel is padded with zero rows. The bias is padded the same way.
///
/// Every entry of Y is computed as ((b_i + a_i0 x_0j) + a_i1 x_1j) + … in column order (fused
/// multiply-adds where the instruction set has them),
/// whatever the number of columns of X and whichever block a column falls in, so a sample's
/// result does not depend on the batch it is evaluated with.
///
/// A short matrix (W or Wᵀ with at most a quarter of a register's rows: a network's output
/// layer, 1 row for the cart pole, 4 for guidance, with float and AVX-512) would leave most
/// lanes of its one panel idle. It is kept row-major instead, and each entry is a dot product
/// along the row: lane-wise partial sums over whole registers of a_i· and x_·j, reduced by
/// Eigen's `predux`, added to b_i, then the remaining cols mod kLanes terms in order. That
/// order, too, depends on the shapes only.
#include <algorithm>
#include <cmath>

#include <Eigen/Core>

#include "sbptt/core/count_dispatch.hpp"
#include "sbptt/core/types.hpp"
#include "sbptt/core/unroll.hpp"
#include "sbptt/core/first_lanes.hpp"
#include "sbptt/core/fused_multiply_add.hpp"
#include "sbptt/core/transpose_tile.hpp"
#include "sbptt/nn/product_destination.hpp"

namespace sbptt {

/// A matrix in the panel layout of the file comment, with an optional bias.
template <class Scalar>
class PackedMatrix {
public:
  using Packet = typename Eigen::internal::packet_traits<Scalar>::type;
  /// Rows per panel: the scalars in one SIMD register of the build's instruction set.
  static constexpr Index kLanes = Eigen::internal::unpacket_traits<Packet>::size;

  [[nodiscard]] Index rows() const { return rows_; }
  [[nodiscard]] Index cols() const { return cols_; }

  /// Packs the row-major `rows × cols` matrix at `row_major` (or its transpose, `cols × rows`,
  /// when `transpose`), with `bias` (rows() entries) or none. The storage only grows, so that
  /// packing matrices of several shapes in turn allocates nothing once the largest was seen.
  void pack(const Scalar* row_major, Index rows, Index cols, bool transpose,
            const Scalar* bias = nullptr) {
    rows_ = transpose ? cols : rows;
    cols_ = transpose ? rows : cols;
    const Index panels = (rows_ + kLanes - 1) / kLanes;
    grow_and_zero(data_, by_rows() ? rows_ * cols_ : panels * kLanes * cols_);
    grow_and_zero(bias_, panels * kLanes);
    // Loops ordered so that the transposed case (Wᵀ, packed at every parameter update along
    // with W) copies contiguous runs of a source row.
    if (by_rows()) {
      for (Index i = 0; i < rows_; ++i)
        for (Index c = 0; c < cols_; ++c)
          data_(i * cols_ + c) = transpose ? row_major[c * cols + i] : row_major[i * cols + c];
    } else if (transpose) {
      for (Index p = 0; p < panels; ++p) {
        const Index lanes = std::min(kLanes, rows_ - p * kLanes);
        Scalar* panel = data_.data() + p * kLanes * cols_;
        const Scalar* source = row_major + p * kLanes;
        // A whole panel's column as one register: copy_n of a run only known at run time
        // was a library call per column (100 × 100 Wᵀ in float: 3.5–3.7 µs against
        // 0.60–0.62; docs/benchmark-runs.md, twenty-second run).
        if (lanes == kLanes) {
          for (Index c = 0; c < cols_; ++c)
            Eigen::internal::pstoreu(panel + c * kLanes,
                                     Eigen::internal::ploadu<Packet>(source + c * cols));
        } else {
          for (Index c = 0; c < cols_; ++c)
            std::copy_n(source + c * cols, lanes, panel + c * kLanes);
        }
      }
    } else {
      for (Index p = 0; p < panels; ++p) {
        const Index lanes = std::min(kLanes, rows_ - p * kLanes);
        Scalar* panel = data_.data() + p * kLanes * cols_;
        const Scalar* source = row_major + p * kLanes * cols;
        Index c = 0;
        if (lanes == kLanes) c = pack_tiles(source, cols, panel);
        for (; c < cols_; ++c)
          for (Index l = 0; l < lanes; ++l) panel[c * kLanes + l] = source[l * cols + c];
      }
    }
    if (bias != nullptr) bias_.head(rows_) = Eigen::Map<const Vector<Scalar>>(bias, rows_);
  }

  /// Y = A X + b: `x` is cols() × n column-major with leading dimension `ldx`, `y` rows() × n
  /// column-major with leading dimension `ldy` (overwritten; it must not overlap `x`).
  /// With `tanh_outputs` = T (rows() × n, leading dimension `ldy`), Y = (A X + b) ⊙ (1 − T²)
  /// instead, applied to each register as it is stored (product_destination.hpp).
  void multiply(const Scalar* x, Index ldx, Index n, Scalar* y, Index ldy,
                const Scalar* tanh_outputs = nullptr) const;

private:
  // Accumulators of a 2-panel block, plus the two weight registers and a broadcast, must fit
  // in the register file (32 registers with AVX-512, 16 with SSE/AVX on x86-64).
  static constexpr int kColumnBlock = EIGEN_ARCH_DEFAULT_NUMBER_OF_REGISTERS >= 32 ? 8 : 4;

  using Destination = detail::ProductDestination<Scalar>;

  /// Columns 0 … Columns − 1 (1 or 2) of every row, in blocks of enough panels for about 8
  /// independent chains of multiply-adds, which hide their latency at two a cycle, where the
  /// accumulators, the panels' weights and a broadcast fit in the registers (with 16: 7 panels
  /// of one column, 4 of two); the last block smaller.
  template <int Columns>
  void narrow_columns(Index panels, const Scalar* x, Index ldx, const Destination& out) const {
    constexpr int block_panels =
        EIGEN_ARCH_DEFAULT_NUMBER_OF_REGISTERS >= 32 ? 8 : (Columns == 1 ? 7 : 4);
    Index p = 0;
    for (; p + block_panels <= panels; p += block_panels)
      block_at<block_panels, Columns>(p, x, ldx, out);
    detail::with_count<block_panels - 1>(panels - p, [&](auto count) {
      block_at<decltype(count)::value, Columns>(p, x, ldx, out);
    });
  }

  /// `block` for the Panels panels from p, the last panel of A at the narrowest width that
  /// holds its rows where that is cheaper (`kNarrowLastPanel`).
  template <int Panels, int Columns>
  void block_at(Index p, const Scalar* x, Index ldx, const Destination& out) const {
    if constexpr (kNarrowLastPanel) {
      const Index last_rows = rows_ - (p + Panels - 1) * kLanes;  // in the block's last panel
      if (4 * last_rows <= kLanes) return block<Panels, Columns, 4>(p, x, ldx, out);
      if (2 * last_rows <= kLanes) return block<Panels, Columns, 2>(p, x, ldx, out);
    }
    block<Panels, Columns, 1>(p, x, ldx, out);
  }

  /// Rows p·kLanes … (p + Panels)·kLanes − 1 of Y, columns 0 … Columns − 1, the last panel in
  /// the lower 1/LastFraction of its registers (1: whole); its loops over registers are
  /// `static_for`s (core/unroll.hpp). Never inlined: inlined into `multiply`'s loops, the same
  /// block made guidance's R epoch 2% slower at -O3 than the plain loops; kept apart, 7–8%
  /// faster (13.59–13.78 against 14.79–15.02 ms; docs/benchmark-runs.md, seventeenth run).
  template <int Panels, int Columns, int LastFraction>
  [[gnu::noinline]] void block(Index p, const Scalar* x, Index ldx,
                               const Destination& out) const {
    using Eigen::internal::pset1;
    Packet acc[Panels][Columns];
    const Scalar* a[Panels];
    detail::static_for<Panels>([&](auto q) SBPTT_ALWAYS_INLINE {
      const Packet b = load<fraction<Panels, LastFraction>(q)>(bias_.data() + (p + q) * kLanes);
      detail::static_for<Columns>([&](auto c) SBPTT_ALWAYS_INLINE { acc[q][c] = b; });
      a[q] = data_.data() + (p + q) * kLanes * cols_;
    });
    for (Index k = 0; k < cols_; ++k) {
      Packet w[Panels];
      detail::static_for<Panels>([&](auto q) SBPTT_ALWAYS_INLINE {
        w[q] = load<fraction<Panels, LastFraction>(q)>(a[q] + k * kLanes);
      });
      detail::static_for<Columns>([&](auto c) SBPTT_ALWAYS_INLINE {
        const Packet xk = pset1<Packet>(x[k + c * ldx]);
        detail::static_for<Panels>([&](auto q) SBPTT_ALWAYS_INLINE {
          acc[q][c] = madd<fraction<Panels, LastFraction>(q)>(w[q], xk, acc[q][c]);
        });
      });
    }
    detail::static_for<Panels>([&](auto q) SBPTT_ALWAYS_INLINE {
      const Index first = (p + q) * kLanes;
      const Index count = std::min(kLanes, rows_ - first);
      detail::static_for<Columns>([&](auto c) SBPTT_ALWAYS_INLINE {
        out.store(first, c, count, acc[q][c]);
      });
    });
  }

  // Where a core splits a 512-bit multiply-add in two 256-bit halves (AMD Zen 4), a last
  // panel of 4 rows in a whole register costs as much as one of 16: the 100 × 100 Wᵀ product
  // at 8 columns in float (its 7th panel of 4 rows at a quarter of the width) took 1474–1476
  // ns against 1596–1604 (docs/benchmark-runs-zen4.md, thirty-third run). AVX-512 builds
  // only; the others are unchanged.
#if defined(EIGEN_VECTORIZE_AVX512)
  static constexpr bool kNarrowLastPanel = FloatOrDouble<Scalar>;
#else
  static constexpr bool kNarrowLastPanel = false;
#endif

  /// The width of panel q of a block: the last in 1/LastFraction of a register, the others whole.
  template <int Panels, int LastFraction>
  static constexpr int fraction(int q) {
    if (q == Panels - 1) return LastFraction;
    return 1;
  }
  /// A panel's column (or bias) of kLanes scalars, its first 1/Fraction by a load of that width.
  template <int Fraction>
  SBPTT_ALWAYS_INLINE static Packet load(const Scalar* from) {
    static_assert(Fraction == 1 || kNarrowLastPanel);
#if defined(EIGEN_VECTORIZE_AVX512)
    if constexpr (Fraction != 1) return detail::load_lower_part<Fraction>(from);
#endif
    return Eigen::internal::ploadu<Packet>(from);
  }
  /// w·x + acc in the first 1/Fraction of the registers.
  template <int Fraction>
  SBPTT_ALWAYS_INLINE static Packet madd(const Packet& w, const Packet& x, const Packet& acc) {
    static_assert(Fraction == 1 || kNarrowLastPanel);
#if defined(EIGEN_VECTORIZE_AVX512)
    if constexpr (Fraction != 1) return detail::lower_madd<Fraction, Scalar>(w, x, acc);
#endif
    return Eigen::internal::pmadd(w, x, acc);
  }

  /// Whether A is short and kept in the row-major layout of the file comment.
  [[nodiscard]] bool by_rows() const { return rows_ <= kMaxShortRows; }
  // A quarter of a register's rows (file comment).
  static constexpr int kMaxShortRows = static_cast<int>(kLanes / 4);
  // The dot products `row_dots` takes side by side: measured, 8 beat 4 and 16.
  static constexpr int kDotsInFlight = 8;
  static_assert(kMaxShortRows <= kDotsInFlight, "all short rows side by side");

  /// Y's entries (i, j), i < Rows = rows(), j < Columns, each b_i + a_i· x_j in the order of
  /// the file comment (short matrices). The Rows × Columns dot products go side by side: one
  /// at a time, each waited on its own chain of multiply-adds and its reduction (float,
  /// 4 × 100 × 8, guidance's output layer: 120–124 ns one at a time, 101–103 side by side;
  /// 1 × 100 × 8, the cart pole's: 32–38 against 25–26; docs/benchmark-runs.md, seventeenth
  /// run).
  template <int Rows, int Columns>
  void row_dots(const Scalar* x, Index ldx, const Destination& out) const {
    using Eigen::internal::pmadd;
    using Eigen::internal::ploadu;
    const Index whole = cols_ / kLanes * kLanes;
    Packet acc[Rows][Columns];
    SBPTT_UNROLL
    for (int r = 0; r < Rows; ++r) {
      SBPTT_UNROLL
      for (int c = 0; c < Columns; ++c) acc[r][c] = Eigen::internal::pset1<Packet>(Scalar(0));
    }
    for (Index k = 0; k < whole; k += kLanes) {
      Packet xk[Columns];
      SBPTT_UNROLL
      for (int c = 0; c < Columns; ++c) xk[c] = ploadu<Packet>(x + c * ldx + k);
      SBPTT_UNROLL
      for (int r = 0; r < Rows; ++r) {
        const Packet a = ploadu<Packet>(data_.data() + r * cols_ + k);
        SBPTT_UNROLL
        for (int c = 0; c < Columns; ++c) acc[r][c] = pmadd(a, xk[c], acc[r][c]);
      }
    }
    SBPTT_UNROLL
    for (int r = 0; r < Rows; ++r) {
      const Scalar* a = data_.data() + r * cols_;
      SBPTT_UNROLL
      for (int c = 0; c < Columns; ++c) {
        Scalar sum = bias_(r);
        if (whole > 0) sum += Eigen::internal::predux(acc[r][c]);
        // std::fma where FMA exists: a plain a·x + sum may be contracted in one inlined copy
        // of this loop and not in another, and a column would depend on its batch.
        for (Index k = whole; k < cols_; ++k)
          sum = detail::fused_multiply_add(a[k], x[c * ldx + k], sum);
        out.store(r, c, sum);
      }
    }
  }

  /// The columns of a whole panel (kLanes rows of the row-major `source`, leading dimension
  /// `ld`) into `panel`, kLanes × kLanes tiles at a time, each transposed in registers
  /// (AVX-512 only); returns the columns done, the rest being fewer than a tile. A 100 × 100 W
  /// in float: 2.7–2.8 µs entry by entry, 0.81–0.84 µs by tiles (docs/benchmark-runs.md,
  /// twenty-second run).
  Index pack_tiles([[maybe_unused]] const Scalar* source, [[maybe_unused]] Index ld,
                   [[maybe_unused]] Scalar* panel) const {
    Index c = 0;
#if defined(EIGEN_VECTORIZE_AVX512)
    if constexpr (FloatOrDouble<Scalar>) {
      for (; c + kLanes <= cols_; c += kLanes) {
        Packet tile[kLanes];
        detail::static_for<static_cast<int>(kLanes)>([&](auto l) SBPTT_ALWAYS_INLINE {
          tile[l] = Eigen::internal::ploadu<Packet>(source + l * ld + c);
        });
        detail::transpose_tile<Scalar>(tile);
        detail::static_for<static_cast<int>(kLanes)>([&](auto k) SBPTT_ALWAYS_INLINE {
          Eigen::internal::pstoreu(panel + (c + k) * kLanes, tile[k]);
        });
      }
    }
#endif
    return c;
  }

  static void grow_and_zero(Vector<Scalar>& storage, Index size) {
    if (storage.size() < size) storage.resize(size);
    storage.head(size).setZero();
  }

  Index rows_ = 0;
  Index cols_ = 0;
  Vector<Scalar> data_;
  Vector<Scalar> bias_;
};

// Defined apart from the class, so that it is not inline: with SBPTT_SEPARATE_KERNELS an
// explicit instantiation declaration (end of this file) then keeps every translation unit but
// one from instantiating it and the kernels it calls.
template <class Scalar>
void PackedMatrix<Scalar>::multiply(const Scalar* x, Index ldx, Index n, Scalar* y,
                                    Index ldy, const Scalar* tanh_outputs) const {
  const Destination out{y, ldy, tanh_outputs};
  if (by_rows()) {
    detail::with_count<kMaxShortRows>(rows_, [&](auto rows) {
      constexpr int r = decltype(rows)::value;
      constexpr int columns = kDotsInFlight / r;
      Index j = 0;
      for (; j + columns <= n; j += columns)
        row_dots<r, columns>(x + j * ldx, ldx, out.from_column(j));
      detail::with_count<columns - 1>(n - j, [&](auto left) {
        row_dots<r, decltype(left)::value>(x + j * ldx, ldx, out.from_column(j));
      });
    });
    return;
  }
  const Index panels = (rows_ + kLanes - 1) / kLanes;
  const Index full_panels = rows_ / kLanes;
  // With 4-column blocks, the panels left after the pairs (an odd count, or a partial last
  // panel) go 8 columns at a time first: alone at 4 columns they keep only 4 multiply-adds
  // in flight, so the last panel of a 100-row matrix cost as much as a pair.
  Index unpaired_done = 0;  // columns of the unpaired panels done 8 at a time
  if constexpr (kColumnBlock == 4) {
    const Index unpaired_from = full_panels - full_panels % 2;  // where the pairs stop
    for (; unpaired_done + 8 <= n; unpaired_done += 8)
      for (Index p = unpaired_from; p < panels; ++p)
        block_at<1, 8>(p, x + unpaired_done * ldx, ldx, out.from_column(unpaired_done));
  }
  Index j = 0;
  auto blocks_of = [&](auto columns) {
    constexpr int width = decltype(columns)::value;
    for (; j + width <= n; j += width) {
      Index p = 0;
      // An odd last panel goes with the two before it where three panels' accumulators,
      // weights and a broadcast leave a register spare: a lone panel keeps only `width`
      // multiply-adds in flight. At 4 columns pairs stop at the last whole panel: pairing a
      // partial one too made GCC 12's code 10% slower, 443–449 against 396–410 ns for
      // 100 × 100 (docs/benchmark-runs.md, fifteenth run). At 8 columns a partial panel pairs
      // too: the quantum CNN's 60 rows (4 panels, the last of 12 rows) went as a pair and two
      // lone panels, 60 × 180 × 56 in float 8425 ns against 7860 paired
      // (docs/benchmark-runs-intel.md, twenty-third run; measured with AVX-512 only, the one
      // x86 target with 8-column blocks).
      constexpr bool last_three = 3 * width + 4 < EIGEN_ARCH_DEFAULT_NUMBER_OF_REGISTERS;
      const Index before_three =
          last_three && panels >= 3 && panels % 2 == 1 ? panels - 3 : panels;
      const Index paired = width >= 8 ? before_three : std::min(before_three, full_panels);
      // Four panels a block where their accumulators, weights and a broadcast fit, with no
      // register spare (half blocks with AVX-512): each broadcast of X then feeds twice the
      // multiply-adds (100 × 100 × 4 in float: 354.5–358.5 ns against 379.6–392.6;
      // docs/benchmark-runs.md, twenty-second run).
      if constexpr (4 * width + 4 + 1 <= EIGEN_ARCH_DEFAULT_NUMBER_OF_REGISTERS) {
        for (; p + 4 <= full_panels && p + 4 <= paired; p += 4)
          block_at<4, width>(p, x + j * ldx, ldx, out.from_column(j));
      }
      for (; p + 2 <= paired; p += 2)
        block_at<2, width>(p, x + j * ldx, ldx, out.from_column(j));
      if (last_three && p + 3 == panels) {
        block_at<3, width>(p, x + j * ldx, ldx, out.from_column(j));
        p += 3;
      }
      if (j + width <= unpaired_done) continue;
      for (; p < panels; ++p) block_at<1, width>(p, x + j * ldx, ldx, out.from_column(j));
    }
  };
  blocks_of(std::integral_constant<int, kColumnBlock>{});
  // Half a block: a batch split over two threads (the paper's 8 samples, 4 each) still keeps
  // 8 multiply-adds in flight instead of one chain per column.
  if constexpr (kColumnBlock > 4) blocks_of(std::integral_constant<int, 4>{});
  // The last 1 to 3 columns (a batch cut over 3 or more threads has such parts) in blocks of
  // more panels, for the same reason: one panel a block would leave one chain per column.
  if (j + 2 <= n) {
    narrow_columns<2>(panels, x + j * ldx, ldx, out.from_column(j));
    j += 2;
  }
  if (j < n) narrow_columns<1>(panels, x + j * ldx, ldx, out.from_column(j));
}

#if defined(SBPTT_SEPARATE_KERNELS)
// Instantiated once, in cmake/kernel_instances.cpp (docs/testing.md).
extern template void PackedMatrix<float>::multiply(const float*, Index, Index, float*, Index,
                                                   const float*) const;
extern template void PackedMatrix<double>::multiply(const double*, Index, Index, double*, Index,
                                                    const double*) const;
#endif

}  // namespace sbptt
