// The one scan for NaN and Inf (core/non_finite.hpp) against a plain loop over std::isfinite:
// every place in a matrix (rows and columns of whole registers and tails), each kind of
// non-finite value, finite extremes that must pass (the largest finite numbers, denormals,
// −0), and a block of a larger matrix, as the engine scans a part of a batch.
#include <catch2/catch.hpp>

#include <cmath>
#include <limits>
#include <optional>

#include "sbptt/core/non_finite.hpp"

using sbptt::Index;
using sbptt::Matrix;

namespace {

template <class Derived>
std::optional<sbptt::EntryIndex> scan(const Eigen::DenseBase<Derived>& m) {
  for (Index c = 0; c < m.cols(); ++c)
    for (Index r = 0; r < m.rows(); ++r)
      if (!std::isfinite(m(r, c))) return sbptt::EntryIndex{r, c};
  return std::nullopt;
}

}  // namespace

TEMPLATE_TEST_CASE("first_non_finite finds what a loop over isfinite finds", "[core]", float,
                   double) {
  using S = TestType;
  using limits = std::numeric_limits<S>;
  Matrix<S> m(19, 7);
  for (Index i = 0; i < m.size(); ++i)
    m(i) = (i % 5 == 0) ? limits::max() : (i % 5 == 1) ? limits::lowest()
         : (i % 5 == 2) ? limits::denorm_min() : (i % 5 == 3) ? -S(0) : S(i);
  REQUIRE_FALSE(sbptt::first_non_finite(m).has_value());
  REQUIRE_FALSE(sbptt::first_non_finite(Matrix<S>(0, 3)).has_value());
  for (const S bad : {limits::quiet_NaN(), limits::infinity(), -limits::infinity()}) {
    for (Index i = 0; i < m.size(); i += 3) {
      Matrix<S> with = m;
      with(i) = bad;
      with(m.size() - 1) = bad;  // a later one must not win
      const auto expected = scan(with);
      const auto got = sbptt::first_non_finite(with);
      REQUIRE(got.has_value());
      CHECK(got->row == expected->row);
      CHECK(got->column == expected->column);
      // The same through a block whose columns start at column 2.
      const auto block = with.middleCols(2, 4);
      const auto in_block = sbptt::first_non_finite(block);
      REQUIRE(in_block.has_value() == scan(block).has_value());
      if (in_block) CHECK(in_block->column == scan(block)->column);
    }
  }
}

TEMPLATE_TEST_CASE("a finite sum of squares shows every entry finite; otherwise the scan decides",
                   "[core]", float, double) {
  // The sweeps skip the scan when ‖λ‖² or ‖g‖² is finite (engine_buffers.hpp). A NaN or an
  // infinity anywhere must make the sum say no; finite entries whose squares overflow make it
  // say no too, and the scan then finds nothing.
  using S = TestType;
  using limits = std::numeric_limits<S>;
  Matrix<S> m = Matrix<S>::Constant(24, 8, S(0.5));
  CHECK(sbptt::squares_show_all_finite(m.squaredNorm()));
  for (const S bad : {limits::quiet_NaN(), limits::infinity(), -limits::infinity()}) {
    for (Index i = 0; i < m.size(); i += 13) {
      Matrix<S> with = m;
      with(i) = bad;
      CHECK_FALSE(sbptt::squares_show_all_finite(with.squaredNorm()));
    }
  }
  Matrix<S> huge = m;
  huge(5) = limits::max();
  CHECK_FALSE(sbptt::squares_show_all_finite(huge.squaredNorm()));
  CHECK_FALSE(sbptt::first_non_finite(huge).has_value());
}
