#pragma once
/// \file Where the registers of a packed product (packed_product.hpp) go: the first rows of a
/// column of Y, each entry optionally times 1 − t² of a tanh layer's output t. A backward
/// pass's Wᵀ Δ is multiplied by the derivative of the tanh layer below it that way, before it
/// is stored, so that it never makes a round trip through memory.
#include <algorithm>

#include <Eigen/Core>

#include "sbptt/core/first_lanes.hpp"
#include "sbptt/core/fused_multiply_add.hpp"
#include "sbptt/core/types.hpp"
#include "sbptt/core/unroll.hpp"

namespace sbptt::detail {

/// Y (column-major, leading dimension `ld`) and, unless null, the tanh outputs T at the same
/// places: what is stored at an entry of Y is then the product's value times 1 − t².
template <class Scalar>
struct ProductDestination {
  using Packet = typename Eigen::internal::packet_traits<Scalar>::type;
  static constexpr Index kLanes = Eigen::internal::unpacket_traits<Packet>::size;

  Scalar* y;
  Index ld;
  const Scalar* tanh_outputs;

  /// The same from column j on.
  [[nodiscard]] ProductDestination from_column(Index j) const {
    return {y + j * ld, ld, tanh_outputs == nullptr ? nullptr : tanh_outputs + j * ld};
  }

  /// Rows first … first + count − 1 of column c (count ≤ kLanes) from `value`'s first lanes.
  SBPTT_ALWAYS_INLINE void store(Index first, Index c, Index count, Packet value) const {
    using Eigen::internal::pmul;
    const Index at = c * ld + first;
    if (tanh_outputs != nullptr) {
      const Packet t = load_rows(tanh_outputs + at, count);
      value = pmul(value, Eigen::internal::psub(Eigen::internal::pset1<Packet>(Scalar(1)),
                                                pmul(t, t)));
    }
    store_rows(y + at, count, value);
  }

  /// The same for one entry (the dot products of short matrices). 1 − t² by
  /// `fused_multiply_add`, as those dot products add their last terms: a plain expression
  /// could be contracted in one inlined copy and not in another.
  void store(Index row, Index c, Scalar value) const {
    const Index at = c * ld + row;
    if (tanh_outputs != nullptr) {
      const Scalar t = tanh_outputs[at];
      value *= fused_multiply_add(-t, t, Scalar(1));
    }
    y[at] = value;
  }

  /// The first `count` lanes of `value` to `to`: only a panel's real rows go out. With
  /// AVX-512 by a masked store: through a buffer and a copy, the 12 rows of the last panel
  /// made the quantum CNN's first product (60 × 6 × 128, float) take 1187–1306 ns against
  /// 694–702 (docs/benchmark-runs.md, seventeenth run). Always inlined: GCC 12 called it from
  /// the blocks of 3 panels, the accumulator going through memory at each of the 24 calls
  /// (cart pole 4's R epoch, best of 40, 34.5–36.3 ms against 31.8–33.0 inlined, alternating
  /// runs outside the machine's dips; docs/benchmark-runs.md, twenty-third run).
  SBPTT_ALWAYS_INLINE static void store_rows(Scalar* to, Index count, const Packet& value) {
    if (count == kLanes) {
      Eigen::internal::pstoreu(to, value);
      return;
    }
#if defined(EIGEN_VECTORIZE_AVX512)
    if constexpr (FloatOrDouble<Scalar>) {
      store_first_lanes(to, value, count);
      return;
    }
#endif
    alignas(64) Scalar lanes[kLanes];
    Eigen::internal::pstoreu(lanes, value);
    std::copy(lanes, lanes + count, to);
  }

  /// The `count` entries at `from` in the first lanes (the others 0), reading no further.
  SBPTT_ALWAYS_INLINE static Packet load_rows(const Scalar* from, Index count) {
    if (count == kLanes) return Eigen::internal::ploadu<Packet>(from);
#if defined(EIGEN_VECTORIZE_AVX512)
    if constexpr (FloatOrDouble<Scalar>) return load_first_lanes(from, count);
#endif
    alignas(64) Scalar lanes[kLanes] = {};
    std::copy(from, from + count, lanes);
    return Eigen::internal::pload<Packet>(lanes);
  }
};

}  // namespace sbptt::detail
