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
/// With AVX-512 or AVX2 that goes by square tiles of a register's lanes (kLanes × kLanes with
/// AVX-512; with AVX2 a block is two tiles of 8 × 8 floats or 4 × 4 doubles side by side), a
/// column of the tile a register, transposed in registers by core/transpose_tile.hpp.
/// Guidance's `vjp_batch` moves 52 rows in and 28 out per block: entry by entry, about
/// 0.15–0.2 ns an entry (docs/benchmark-runs.md, eighteenth run); by AVX2 tiles its paired VJP
/// of 8 samples took 1170 ns against 1930 (docs/benchmark-runs.md, eighty-second run).
#include <algorithm>
#include <span>

#include <Eigen/Core>

#include "sbptt/core/first_lanes.hpp"
#include "sbptt/core/transpose_tile.hpp"
#include "sbptt/core/types.hpp"
#include "sbptt/core/unroll.hpp"
#include "sbptt/sim/side_by_side.hpp"

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

  using Columns = SideBySide<const Matrix<Scalar>>;
  using ColumnsOut = SideBySide<Matrix<Scalar>>;

  /// Every row of columns first … first + count − 1 of `m` into `rows`, one lane array per row
  /// of `m`, as `load` row by row. Debug builds check that there is one array per row: with too
  /// few the loads write past the caller's arrays (the stores read past them), with too many
  /// the arrays past m.rows() keep stale values that the caller's arithmetic would read.
  EIGEN_ALWAYS_INLINE static void load_rows(const Columns& m, Index first, int count,
                                            std::span<Values> rows) {
    eigen_assert(static_cast<Index>(rows.size()) == m.rows());
    // By pointer from here: a span's operator[] is bounds-checked under _GLIBCXX_ASSERTIONS.
    Values* const out = rows.data();
#if defined(EIGEN_VECTORIZE_AVX512) || defined(EIGEN_VECTORIZE_AVX2)
    if constexpr (kTransposeInRegisters) {
      return load_tiles(m, first, count, out);
    }
#endif
    for (Index r = 0; r < m.rows(); ++r)
      for (int l = 0; l < kLanes; ++l) out[r](l) = l < count ? m.column(first + l)[r] : Scalar(0);
  }
  EIGEN_ALWAYS_INLINE static void load_rows(const Matrix<Scalar>& m, Index first, int count,
                                            std::span<Values> rows) {
    load_rows(Columns{&m}, first, count, rows);
  }

  /// The first `count` lanes of `rows` (one array per row of `m`, checked as in `load_rows`)
  /// into columns first … first + count − 1 of `m`, as `store` row by row.
  EIGEN_ALWAYS_INLINE static void store_rows(std::span<const Values> rows, Index first, int count,
                                             const ColumnsOut& m) {
    eigen_assert(static_cast<Index>(rows.size()) == m.rows());
    const Values* const in = rows.data();
#if defined(EIGEN_VECTORIZE_AVX512) || defined(EIGEN_VECTORIZE_AVX2)
    if constexpr (kTransposeInRegisters) {
      return store_tiles(in, first, count, m);
    }
#endif
    for (Index r = 0; r < m.rows(); ++r)
      for (int l = 0; l < count; ++l) m.column(first + l)[r] = in[r](l);
  }
  EIGEN_ALWAYS_INLINE static void store_rows(std::span<const Values> rows, Index first, int count,
                                             Matrix<Scalar>& m) {
    store_rows(rows, first, count, ColumnsOut{&m});
  }

private:
#if defined(EIGEN_VECTORIZE_AVX512) || defined(EIGEN_VECTORIZE_AVX2)
  static constexpr bool kTransposeInRegisters = FloatOrDouble<Scalar>;
  using Packet = typename Eigen::internal::packet_traits<Scalar>::type;
  /// A register's lanes: a tile is kTile × kTile, and a block kLanes / kTile tiles wide
  /// (one with AVX-512, two with AVX2).
  static constexpr int kTile = Eigen::internal::unpacket_traits<Packet>::size;
  static_assert(kLanes % kTile == 0);
  static Packet zero() { return Eigen::internal::pset1<Packet>(Scalar(0)); }

  EIGEN_ALWAYS_INLINE static void load_tiles(const Columns& m, Index first, int count,
                                             Values* rows) {
    for (Index top = 0; top < m.rows(); top += kTile) {
      const Index height = std::min<Index>(kTile, m.rows() - top);
      SBPTT_UNROLL
      for (int left = 0; left < kLanes; left += kTile) {
        Packet tile[kTile];
        if (left >= count) {  // lanes past the count only: zeros, nothing to transpose
          for (Index i = 0; i < height; ++i)
            Eigen::internal::pstoreu(rows[top + i].data() + left, zero());
          continue;
        }
        SBPTT_UNROLL
        for (int l = 0; l < kTile; ++l)
          tile[l] = left + l < count ? load_first_lanes(m.column(first + left + l) + top, height)
                                     : zero();
        transpose_tile<Scalar>(tile);
        SBPTT_UNROLL
        for (Index i = 0; i < height; ++i)
          Eigen::internal::pstoreu(rows[top + i].data() + left, tile[i]);
      }
    }
  }

  EIGEN_ALWAYS_INLINE static void store_tiles(const Values* rows, Index first, int count,
                                              const ColumnsOut& m) {
    for (Index top = 0; top < m.rows(); top += kTile) {
      const Index height = std::min<Index>(kTile, m.rows() - top);
      SBPTT_UNROLL
      for (int left = 0; left < kLanes && left < count; left += kTile) {
        Packet tile[kTile];
        SBPTT_UNROLL
        for (Index i = 0; i < kTile; ++i)
          tile[i] = i < height ? Eigen::internal::ploadu<Packet>(rows[top + i].data() + left)
                               : zero();
        transpose_tile<Scalar>(tile);
        const int lanes = std::min(kTile, count - left);
        SBPTT_UNROLL
        for (int l = 0; l < lanes; ++l)
          store_first_lanes(m.column(first + left + l) + top, tile[l], height);
      }
    }
  }
#endif
};

}  // namespace sbptt::detail
