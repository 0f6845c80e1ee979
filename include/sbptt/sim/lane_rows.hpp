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
#include <algorithm>

#include <Eigen/Core>

#include "sbptt/core/types.hpp"

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
};

}  // namespace sbptt::detail
