// The scan for NaN and Inf (core/non_finite.hpp) in a program built with -ffinite-math-only, as
// -ffast-math implies (see tests/CMakeLists.txt). There the compiler may take every value for
// finite, and clang 14 then drops the tests Eigen's isFinite makes: the scan found no NaN at
// all. The truth here is where the test put the values, not a library or a standard test.
#include <catch2/catch.hpp>

#include <bit>
#include <cstdint>
#include <limits>
#include <type_traits>

#include "sbptt/core/non_finite.hpp"

using sbptt::Index;
using sbptt::Matrix;

namespace {

// NaN and ±Inf made from their bits, which no optimisation can take for a finite number.
template <class S>
S from_bits(std::uint64_t double_bits, std::uint32_t float_bits) {
  if constexpr (std::is_same_v<S, float>) {
    return std::bit_cast<float>(float_bits);
  } else {
    return std::bit_cast<double>(double_bits);
  }
}

}  // namespace

TEMPLATE_TEST_CASE("under -ffinite-math-only first_non_finite still finds NaN and Inf",
                   "[core]", float, double) {
  using S = TestType;
  using limits = std::numeric_limits<S>;
  const S quiet_nan = from_bits<S>(0x7ff8000000000000ULL, 0x7fc00000U);
  const S negative_nan = from_bits<S>(0xfff8000000000001ULL, 0xffc00001U);
  const S infinity = from_bits<S>(0x7ff0000000000000ULL, 0x7f800000U);
  const S negative_infinity = from_bits<S>(0xfff0000000000000ULL, 0xff800000U);
  Matrix<S> m(19, 7);
  for (Index i = 0; i < m.size(); ++i)
    m(i) = (i % 4 == 0) ? limits::max() : (i % 4 == 1) ? limits::lowest()
         : (i % 4 == 2) ? limits::denorm_min() : S(i);
  REQUIRE_FALSE(sbptt::first_non_finite(m).has_value());
  for (const S bad : {quiet_nan, negative_nan, infinity, negative_infinity}) {
    for (Index i = 0; i < m.size(); i += 5) {
      INFO("entry " << i);
      Matrix<S> with = m;
      with(i) = bad;
      with(m.size() - 1) = bad;  // a later one must not win
      const auto got = sbptt::first_non_finite(with);
      REQUIRE(got.has_value());
      CHECK(got->row == i % m.rows());
      CHECK(got->column == i / m.rows());
      // The same through a block that starts at column 2 and a map of the whole matrix.
      const Index column = i / m.rows();
      const auto in_block = sbptt::first_non_finite(with.middleCols(2, 4));
      if (column >= 2 && column < 6) {
        REQUIRE(in_block.has_value());
        CHECK(in_block->row == i % m.rows());
        CHECK(in_block->column == column - 2);
      }
      const auto in_map =
          sbptt::first_non_finite(Eigen::Map<const Matrix<S>>(with.data(), m.rows(), m.cols()));
      REQUIRE(in_map.has_value());
      CHECK(in_map->column == column);
    }
  }
}
