#pragma once
/// \file dW += D Xᵀ: the parameter product of a layer, summed over the batch.
///
/// A dense layer's parameter VJP (and a convolution's, over its im2col matrix) adds the outer
/// product of each sample's pre-activation adjoint d_k and input x_k to the row-major weight
/// gradient: dW += Σ_k d_k x_kᵀ. At the paper's batch of 8 the inner dimension is 8, and a
/// general matrix product packs both operands and then loads and stores all of dW around
/// those 8 multiply-adds: Eigen runs the 100 × 100 × 8 product at about 120 GFLOP/s on an
/// AVX-512 core that peaks near 200 (docs/benchmark-runs.md, fourth run). The kernel below
/// keeps a block of X (3 column panels × 8 samples) in registers and streams the rows of dW
/// past it, which runs at about 230.
///
/// It needs 32 vector registers and masked loads and stores for the rows' last panel, so it is
/// compiled for AVX-512 only, and used for rows of 2 or more entries (float, 8 samples: 100 ×
/// 10 in 141–145 ns against Eigen's 404, 100 × 6 in 149 against 422, 100 × 2 in 148 against
/// 276). Rows of one entry (100 × 1: 303 against 46 ns) use Eigen's product. With AVX2's 16
/// registers the same scheme, holding 8 × 1 panels, measured slower than Eigen; AVX2 builds
/// with FMA keep a block of dW in the registers instead (outer_product_avx2.hpp), and other
/// builds use Eigen's product.
///
/// In the kernel every entry is ((dW_ij + d_i0 x'_j0) + d_i1 x'_j1) + … in sample order with
/// fused multiply-adds, x' = s·x rounded (x itself without a scale), whatever the shapes;
/// Eigen's product has an order of its own. Either way the order depends only on the shapes,
/// so results do not depend on the thread count.
#include <type_traits>

#include <Eigen/Core>

#include "sbptt/core/count_dispatch.hpp"
#include "sbptt/core/error.hpp"
#include "sbptt/core/types.hpp"
#include "sbptt/core/unroll.hpp"
#include "sbptt/core/first_lanes.hpp"
#include "sbptt/nn/outer_product_avx2.hpp"
#include "sbptt/nn/quarter_strip.hpp"

namespace sbptt {
namespace detail {

#if defined(EIGEN_VECTORIZE_AVX512)
/// The register-blocked kernel of the file comment; `Scalar` is float or double.
template <class Scalar>
class OuterProductKernel {
public:
  using Packet = typename Eigen::internal::packet_traits<Scalar>::type;
  static constexpr Index kLanes = Eigen::internal::unpacket_traits<Packet>::size;
  static constexpr Index kHalfLanes = kLanes / 2;
  static constexpr Index kQuarterLanes = kLanes / 4;

  /// dW (rows × cols, row-major) += D (rows × n, column-major) diag(s) Xᵀ (X: cols × n,
  /// column-major; s: n entries, or none for s = 1).
  static void run(Scalar* dw, Index rows, Index cols, const Scalar* d, const Scalar* x,
                  Index n, const Scalar* scale) {
    Index k = 0;
    for (; k + kSamples <= n; k += kSamples)
      samples<kSamples>(dw, rows, cols, d + k * rows, x + k * cols, at(scale, k));
    // The 1 … kSamples − 1 samples after the last full group, by a kernel of that width.
    with_count<kSamples - 1>(n - k, [&](auto count) {
      samples<decltype(count)::value>(dw, rows, cols, d + k * rows, x + k * cols, at(scale, k));
    });
  }

private:
  // X's block (kPanels × kSamples registers), kRows × kPanels accumulators and a broadcast:
  // 24 + 6 + 1 of the 32 registers. A block with a row's partial last panel and whole panels
  // before it, or a row narrower than a register, goes one row at a time (kMaskedRows):
  // 100 × 24 × 8 in 215–224 ns against 254–267 for the whole panel and the partial one in
  // blocks of 2 rows each. A partial panel alone after the blocks keeps kRows.
  static constexpr int kSamples = 8;
  static constexpr int kPanels = 3;
  static constexpr int kRows = 2;
  // One row a block is also what lets `columns` order the rows in passes.
  static constexpr int kMaskedRows = 1;
  /// How a block's last panel covers its columns: a whole register, the first lanes of one
  /// (masked loads and stores), or exactly half or a quarter of one (half- or quarter-width
  /// instructions). Where a core splits a 512-bit multiply-add in two 256-bit halves (AMD Zen
  /// 4), a masked register costs a whole one and half a register half of one: 100 × 24 × 8 in
  /// float with its bias in 430–432 ns against 482–487 masked (docs/benchmark-runs-zen4.md,
  /// thirty-second run). The lanes summed are the same, so are the bits. Blocks with a half
  /// or a quarter go kRows rows at a time: no store reaches past its row.
  enum class Last { Whole, Masked, Half, Quarter };

  static const Scalar* at(const Scalar* scale, Index k) {
    return scale == nullptr ? nullptr : scale + k;
  }

  /// One pass over dW adding `Samples` samples' outer products: blocks of kPanels column
  /// panels, then one more block with the whole panels left and a row's partial last panel
  /// (half- or quarter-width when it is half or a quarter of a register; on its own when no
  /// whole panel is left, a quarter then by quarter_strip.hpp).
  template <int Samples>
  static void samples(Scalar* dw, Index rows, Index cols, const Scalar* d, const Scalar* x,
                      const Scalar* scale) {
    static_assert(kMaskedRows == 1, "a masked block at column 0 needs its rows in passes");
    const Index full_panels = cols / kLanes;
    const bool partial = full_panels * kLanes < cols;
    // A last quarter goes in a block with up to two whole panels, never alone after the
    // blocks of kPanels: 100 × 100 × 8 in float in 1467.6–1475.8 ns as 3 + 1 + (2 + ¼)
    // panels, against 1531.2–1535.3 as 3 + 3 and then quarter_strip.hpp
    // (docs/benchmark-runs-zen4.md, thirty-eighth run).
    const bool quarter_last = full_panels > 0 && cols - full_panels * kLanes == kQuarterLanes;
    const Index panels_in_blocks = quarter_last ? full_panels - 1 : full_panels;
    Index p = 0;
    for (; p + kPanels <= panels_in_blocks; p += kPanels)
      columns<Samples, kPanels, Last::Whole>(dw, rows, cols, d, x, scale, p * kLanes);
    Index left = full_panels - p;  // whole panels after the blocks: 0, 1, 2 (quarter: 1, 2, 3)
    Index first = p * kLanes;
    if (quarter_last) {
      if (left == kPanels) {
        columns<Samples, 1, Last::Whole>(dw, rows, cols, d, x, scale, first);
        first += kLanes;
        --left;
      }
      with_count<2>(left, [&](auto panels) {  // the whole panels left and the quarter
        columns<Samples, decltype(panels)::value + 1, Last::Quarter>(dw, rows, cols, d, x, scale,
                                                                     first);
      });
    } else if (!partial) {
      if (left == 2) columns<Samples, 2, Last::Whole>(dw, rows, cols, d, x, scale, first);
      if (left == 1) columns<Samples, 1, Last::Whole>(dw, rows, cols, d, x, scale, first);
    } else if (cols - first - left * kLanes == kHalfLanes) {
      with_count<3>(left + 1, [&](auto panels) {  // the whole panels left and the half
        columns<Samples, decltype(panels)::value, Last::Half>(dw, rows, cols, d, x, scale, first);
      });
    } else if (left == 2) {
      columns<Samples, 3, Last::Masked, kMaskedRows>(dw, rows, cols, d, x, scale, first);
    } else if (left == 1) {
      columns<Samples, 2, Last::Masked, kMaskedRows>(dw, rows, cols, d, x, scale, first);
    } else if (cols - first == QuarterStrip<Scalar>::kWidth) {
      QuarterStrip<Scalar>::template add<Samples>(dw, rows, cols, d, x, scale, first);
    } else if (full_panels == 0) {
      columns<Samples, 1, Last::Masked, kMaskedRows>(dw, rows, cols, d, x, scale, first);
    } else {
      columns<Samples, 1, Last::Masked>(dw, rows, cols, d, x, scale, first);
    }
  }

  /// Columns first … first + Panels·kLanes − 1 of every row, the last panel only up to cols
  /// when masked, half or quarter (`LastPanel`), in blocks of `Rows` rows. A scale multiplies
  /// X's block in the registers, once for all rows.
  template <int Samples, int Panels, Last LastPanel, int Rows = kRows>
  static void columns(Scalar* dw, Index rows, Index cols, const Scalar* d, const Scalar* x,
                      const Scalar* scale, Index first) {
    constexpr bool masked = LastPanel == Last::Masked;
    const Index lanes = masked ? cols - first - (Panels - 1) * kLanes : kLanes;
    Packet xs[Panels][Samples];
    SBPTT_UNROLL
    for (int p = 0; p < Panels; ++p) {
      SBPTT_UNROLL
      for (int k = 0; k < Samples; ++k)
        xs[p][k] = load_panel<Panels, LastPanel>(x + k * cols + first + p * kLanes, p, lanes);
    }
    if (scale != nullptr) {
      SBPTT_UNROLL
      for (int k = 0; k < Samples; ++k) {
        SBPTT_UNROLL
        for (int p = 0; p < Panels; ++p)
          xs[p][k] = Eigen::internal::pmul(xs[p][k], Eigen::internal::pset1<Packet>(scale[k]));
      }
    }
    Index i = 0;
    if constexpr (Rows > 1) {
      for (; i + Rows <= rows; i += Rows)
        update_rows<Samples, Panels, Rows, LastPanel>(dw + i * cols + first, cols, d + i, rows,
                                                      xs, lanes);
    }
    // The rows left, one at a time (all of them in a block of one row). A masked store
    // reaches up to a register past the end of its row, and a load that overlaps a store
    // still in flight waits until it is written, even where only masked-off lanes overlap.
    // Where the block starts its rows (first = 0) the next rows' loads would overlap, so the
    // rows go in `stride` passes, each taking every stride-th row: a row's block spans
    // Panels·kLanes entries, and the next row visited starts at or after their end (100 × 10
    // × 8 took 1220 ns in row order, 141 ns in two passes). A block after the first 3 panels
    // starts 3 registers into its row, further than any store reaches past the row before, so
    // it needs no passes; `samples` gives the blocks at column 0 one row at a time.
    const Index span = Panels * kLanes;
    const Index stride = Rows == 1 && masked && first == 0 ? (span + cols - 1) / cols : 1;
    for (Index start = i; start < i + stride; ++start)
      for (Index r = start; r < rows; r += stride)
        update_rows<Samples, Panels, 1, LastPanel>(dw + r * cols + first, cols, d + r, rows, xs,
                                                   lanes);
  }

  template <int Samples, int Panels, int Rows, Last LastPanel>
  EIGEN_ALWAYS_INLINE static void update_rows(Scalar* dw, Index ldw, const Scalar* d, Index ldd,
                                              const Packet (&xs)[Panels][Samples],
                                              Index lanes) {
    Packet acc[Rows][Panels];
    SBPTT_UNROLL
    for (int r = 0; r < Rows; ++r) {
      SBPTT_UNROLL
      for (int p = 0; p < Panels; ++p)
        acc[r][p] = load_panel<Panels, LastPanel>(dw + r * ldw + p * kLanes, p, lanes);
    }
    SBPTT_UNROLL
    for (int k = 0; k < Samples; ++k) {
      SBPTT_UNROLL
      for (int r = 0; r < Rows; ++r) {
        const Packet dk = Eigen::internal::pset1<Packet>(d[r + k * ldd]);
        SBPTT_UNROLL
        for (int p = 0; p < Panels; ++p)
          acc[r][p] = madd_panel<Panels, LastPanel>(xs[p][k], dk, acc[r][p], p);
      }
    }
    SBPTT_UNROLL
    for (int r = 0; r < Rows; ++r) {
      SBPTT_UNROLL
      for (int p = 0; p < Panels; ++p)
        store_panel<Panels, LastPanel>(dw + r * ldw + p * kLanes, acc[r][p], p, lanes);
    }
  }

  /// Panel p of a block whose last panel is as `LastPanel` says (masked: its first `lanes`
  /// lanes; half or quarter: the lower half or quarter of the register, the rest undefined).
  template <int Panels, Last LastPanel>
  EIGEN_ALWAYS_INLINE static Packet load_panel(const Scalar* from, int p, Index lanes) {
    if (p == Panels - 1) {
      if constexpr (LastPanel == Last::Masked) return load_first_lanes(from, lanes);
      if constexpr (LastPanel == Last::Half) return load_lower_part<2>(from);
      if constexpr (LastPanel == Last::Quarter) return load_lower_part<4>(from);
    }
    return Eigen::internal::ploadu<Packet>(from);
  }
  /// x·d + acc for panel p, at half or quarter width for such a last panel.
  template <int Panels, Last LastPanel>
  EIGEN_ALWAYS_INLINE static Packet madd_panel(const Packet& x, const Packet& d,
                                               const Packet& acc, int p) {
    if (LastPanel == Last::Half && p == Panels - 1) return lower_madd<2, Scalar>(x, d, acc);
    if (LastPanel == Last::Quarter && p == Panels - 1) return lower_madd<4, Scalar>(x, d, acc);
    return Eigen::internal::pmadd(x, d, acc);
  }
  template <int Panels, Last LastPanel>
  EIGEN_ALWAYS_INLINE static void store_panel(Scalar* to, const Packet& value, int p,
                                              Index lanes) {
    if (LastPanel == Last::Masked && p == Panels - 1) {
      store_first_lanes(to, value, lanes);
    } else if (LastPanel == Last::Half && p == Panels - 1) {
      Eigen::internal::pstoreu(to, lower_part<2, Scalar>(value));
    } else if (LastPanel == Last::Quarter && p == Panels - 1) {
      Eigen::internal::pstoreu(to, lower_part<4, Scalar>(value));
    } else {
      Eigen::internal::pstoreu(to, value);
    }
  }
};
#endif

#if defined(EIGEN_VECTORIZE_AVX512) || defined(SBPTT_OUTER_PRODUCT_AVX2)
/// The registers of `add_sample_sums`: blocks of kRegisters registers of rows, then the rows
/// left (the last register masked). With AVX2 only where it has FMA: a scale comes only with
/// the register kernels, and its sums round d·s + b once.
template <class Scalar>
class SampleSums {
public:
  using Packet = typename Eigen::internal::packet_traits<Scalar>::type;
  static constexpr Index kLanes = Eigen::internal::unpacket_traits<Packet>::size;

  static void run(Scalar* b, Index rows, const Scalar* d, Index n, const Scalar* scale) {
    if (scale == nullptr) {
      rows_in_blocks<false>(b, rows, d, n, scale);
    } else {
      rows_in_blocks<true>(b, rows, d, n, scale);
    }
  }

private:
  // Registers summed at once, each its own chain of additions: for 100 rows × 8 samples in
  // float 2 took 17–18.4 ns, 4 and 8 18.0–18.7, and 1 19.0–23.5 (two probes, AVX-512; not
  // measured again for AVX2, where 2 registers of rows took 30 ns: eighty-second run).
  static constexpr int kRegisters = 2;

  template <bool Scaled>
  static void rows_in_blocks(Scalar* b, Index rows, const Scalar* d, Index n,
                             const Scalar* scale) {
    Index r = 0;
    for (; r + kRegisters * kLanes <= rows; r += kRegisters * kLanes)
      sum<kRegisters, Scaled>(b + r, rows, d + r, n, scale, kLanes);
    const Index left = rows - r;
    const Index last_lanes = left % kLanes == 0 ? kLanes : left % kLanes;
    with_count<kRegisters>((left + kLanes - 1) / kLanes, [&](auto registers) {
      sum<decltype(registers)::value, Scaled>(b + r, rows, d + r, n, scale, last_lanes);
    });
  }

  /// `Registers` registers of rows from b and d (leading dimension ldd), the last one's first
  /// `last_lanes` lanes only.
  template <int Registers, bool Scaled>
  static void sum(Scalar* b, Index ldd, const Scalar* d, Index n, const Scalar* scale,
                  Index last_lanes) {
    auto load = [&](const Scalar* from, int q) {
      return q == Registers - 1 ? load_first_lanes(from, last_lanes)
                                : Eigen::internal::ploadu<Packet>(from);
    };
    Packet acc[Registers];
    SBPTT_UNROLL
    for (int q = 0; q < Registers; ++q) acc[q] = load(b + q * kLanes, q);
    for (Index k = 0; k < n; ++k) {
      const Scalar* column = d + k * ldd;
      SBPTT_UNROLL
      for (int q = 0; q < Registers; ++q) {
        if constexpr (Scaled) {
          acc[q] = Eigen::internal::pmadd(load(column + q * kLanes, q),
                                          Eigen::internal::pset1<Packet>(scale[k]), acc[q]);
        } else {
          acc[q] = Eigen::internal::padd(acc[q], load(column + q * kLanes, q));
        }
      }
    }
    SBPTT_UNROLL
    for (int q = 0; q < Registers; ++q) {
      if (q == Registers - 1) {
        store_first_lanes(b + q * kLanes, acc[q], last_lanes);
      } else {
        Eigen::internal::pstoreu(b + q * kLanes, acc[q]);
      }
    }
  }
};
#endif

// The register kernel of the build's instruction set, where it has one.
#if defined(EIGEN_VECTORIZE_AVX512)
#define SBPTT_OUTER_PRODUCT_KERNEL 1
template <class Scalar>
using RegisterOuterProduct = OuterProductKernel<Scalar>;
#elif defined(SBPTT_OUTER_PRODUCT_AVX2)
#define SBPTT_OUTER_PRODUCT_KERNEL 1
template <class Scalar>
using RegisterOuterProduct = OuterProductAvx2<Scalar>;
#endif

}  // namespace detail

/// Whether `add_outer_products` runs a register kernel for rows of `cols` entries (AVX-512,
/// or AVX2 with FMA; float or double, 2 or more entries); only then does it take a scale.
/// Rows of one entry stay with Eigen (100 × 1 × 8 in float: 46 ns against 303 with AVX-512,
/// 68–69 against 210 with AVX2).
template <class Scalar>
[[nodiscard]] constexpr bool outer_product_kernel_applies([[maybe_unused]] Index cols) {
#if defined(SBPTT_OUTER_PRODUCT_KERNEL)
  if constexpr (FloatOrDouble<Scalar>)
    return cols >= 2;
#endif
  return false;
}

/// dW += D diag(s) Xᵀ. \param dw  rows × cols, row-major (a weight gradient), accumulated
/// \param d  rows × n, column-major \param x  cols × n, column-major; n is the batch sum
/// \param scale  s, n entries, or null for s = 1; only where `outer_product_kernel_applies`.
template <class Scalar>
void add_outer_products(Scalar* dw, Index rows, Index cols, const Scalar* d, const Scalar* x,
                        Index n, const Scalar* scale = nullptr) {
#if defined(SBPTT_OUTER_PRODUCT_KERNEL)
  if constexpr (FloatOrDouble<Scalar>) {
    if (outer_product_kernel_applies<Scalar>(cols)) {
      detail::RegisterOuterProduct<Scalar>::run(dw, rows, cols, d, x, n, scale);
      return;
    }
  }
#endif
  detail::require(scale == nullptr, "add_outer_products: a scale for rows of ", cols,
                  " entries; expected one only where the register kernel runs");
  Eigen::Map<RowMajorMatrix<Scalar>>(dw, rows, cols).noalias() +=
      Eigen::Map<const Matrix<Scalar>>(d, rows, n) *
      Eigen::Map<const Matrix<Scalar>>(x, cols, n).transpose();
}

namespace detail {

/// db += D s, each entry summed in sample order, ((b_i + d_i0 s_0) + d_i1 s_1) + … (fused
/// multiply-adds with a scale, which only builds with a register kernel take), whatever the
/// rows and the alignment. Eigen's `rowwise().sum()` grouped the samples in its own way, and
/// differently for the rows it reached by registers and those before and after them (where
/// they fell depended on db's address), and took longer (docs/benchmark-runs.md, twenty-first
/// run).
template <class Scalar>
void add_sample_sums(Scalar* b, Index rows, const Scalar* d, Index n, const Scalar* scale) {
#if defined(EIGEN_VECTORIZE_AVX512) || defined(SBPTT_OUTER_PRODUCT_AVX2)
  if constexpr (FloatOrDouble<Scalar>) {
    SampleSums<Scalar>::run(b, rows, d, n, scale);
    return;
  }
#endif
  // No register kernel for this build and Scalar (outer_product_kernel_applies is false), so
  // no scale.
  require(scale == nullptr,
          "add_weight_and_bias_products: a scale where the register kernels do not run; "
          "expected none");
  Eigen::Map<Vector<Scalar>> bias(b, rows);
  for (Index k = 0; k < n; ++k) bias += Eigen::Map<const Vector<Scalar>>(d + k * rows, rows);
}

}  // namespace detail

/// The parameter VJP of a layer whose gradient slice is W (rows × cols, row-major) followed by
/// its bias b (rows), as both Dense and Conv1d lay it out: dW += D diag(s) Xᵀ, db += D s (s = 1
/// without a scale; see `add_outer_products`).
template <class Scalar>
void add_weight_and_bias_products(Scalar* grad, Index rows, Index cols, const Scalar* d,
                                  const Scalar* x, Index n, const Scalar* scale = nullptr) {
  add_outer_products(grad, rows, cols, d, x, n, scale);
  detail::add_sample_sums(grad + rows * cols, rows, d, n, scale);
}

#if defined(SBPTT_SEPARATE_KERNELS)
// Instantiated once, in cmake/kernel_instances.cpp (docs/testing.md).
extern template void add_outer_products(float*, Index, Index, const float*, const float*, Index,
                                        const float*);
extern template void add_outer_products(double*, Index, Index, const double*, const double*,
                                        Index, const double*);
namespace detail {
extern template void add_sample_sums(float*, Index, const float*, Index, const float*);
extern template void add_sample_sums(double*, Index, const double*, Index, const double*);
}  // namespace detail
#endif

}  // namespace sbptt
