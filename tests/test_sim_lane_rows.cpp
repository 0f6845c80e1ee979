// A batch matrix's block of samples into lane arrays and back (sim/lane_rows.hpp): every
// entry against the matrix indexed one entry at a time, for heights that fill no tile, one,
// and several with a partial last one (of every height short of an AVX2 tile, 8 floats or 4
// doubles), every count of samples in a block, blocks that start past column 0 and blocks that
// end at the matrix's last column (a read past the block there leaves the allocation, for a
// sanitizer to see); the lanes past the count are 0, and nothing outside the block or past the
// last lane array is written.
#include <catch2/catch.hpp>

#include <span>
#include <utility>
#include <vector>

#include "support/test_data.hpp"
#include "sbptt/sim/lane_rows.hpp"

using sbptt::Index;
using sbptt::Matrix;
using sbptt::testing::random_matrix;

TEMPLATE_TEST_CASE("lane rows: a block of samples in and out, entry for entry",
                   "[sim][lanes]", float, double) {
  using S = TestType;
  using Lanes = sbptt::detail::LaneRows<S>;
  constexpr int kLanes = Lanes::kLanes;
  std::uint64_t seed = 300;
  for (const Index rows : {1, 2, 3, 5, 6, 7, 8, 9, 14, 15, 16, 17, 24, 28, 33, 40}) {
    for (int count = 1; count <= kLanes; ++count) {
      for (const auto& [first, after] : {std::pair<Index, Index>{0, 2}, {3, 2}, {0, 0}, {3, 0}}) {
        INFO("rows " << rows << " count " << count << " first " << first << " after " << after);
        const Index cols = first + count + after;
        const Matrix<S> m = random_matrix<S>(rows, cols, ++seed, 1.0);
        // One lane array per row of m and one more after them as a sentinel; the functions
        // get only the first `rows`.
        std::vector<typename Lanes::Values> values(static_cast<std::size_t>(rows + 1));
        for (auto& v : values) v.setConstant(S(-9));
        const auto arrays = std::span(values).first(static_cast<std::size_t>(rows));
        Lanes::load_rows(m, first, count, arrays);
        REQUIRE((values.back() == S(-9)).all());
        for (Index r = 0; r < rows; ++r) {
          const auto& v = values[static_cast<std::size_t>(r)];
          for (int l = 0; l < kLanes; ++l)
            REQUIRE(v(l) == (l < count ? m(r, first + l) : S(0)));
          REQUIRE((v == Lanes::load(m, r, first, count)).all());
        }

        for (auto& v : values) v = random_matrix<S>(kLanes, 1, ++seed, 1.0).array();
        const Matrix<S> before = random_matrix<S>(rows, cols, ++seed, 1.0);
        Matrix<S> out = before;
        Lanes::store_rows(arrays, first, count, out);
        for (Index r = 0; r < rows; ++r) {
          for (Index c = 0; c < cols; ++c) {
            const bool in_block = c >= first && c < first + count;
            REQUIRE(out(r, c) ==
                    (in_block ? values[static_cast<std::size_t>(r)](c - first) : before(r, c)));
          }
        }
      }
    }
  }
}

// The combined update's pair hands both sweeps' columns to one block (sim/side_by_side.hpp):
// a block that starts in the left matrix and ends in the right one reads and writes each
// column in its own matrix, with tiles of lanes that span the two.
TEMPLATE_TEST_CASE("lane rows: a block across two matrices side by side", "[sim][lanes]", float,
                   double) {
  using S = TestType;
  using Lanes = sbptt::detail::LaneRows<S>;
  constexpr int kLanes = Lanes::kLanes;
  std::uint64_t seed = 900;
  for (const Index rows : {3, 8, 12, 28}) {
    for (const Index half : {Index{kLanes / 2}, Index{5}, Index{kLanes}}) {
      for (Index first = 0; first < 2 * half; first += 3) {
        const int count = Lanes::count(2 * half, first);
        INFO("rows " << rows << " half " << half << " first " << first);
        const Matrix<S> left = random_matrix<S>(rows, half, ++seed, 1.0);
        const Matrix<S> right = random_matrix<S>(rows, half, ++seed, 1.0);
        const auto entry = [&](const Matrix<S>& a, const Matrix<S>& b, Index r, Index c) {
          return c < half ? a(r, c) : b(r, c - half);
        };
        std::vector<typename Lanes::Values> values(static_cast<std::size_t>(rows));
        Lanes::load_rows(typename Lanes::Columns{&left, &right}, first, count, values);
        for (Index r = 0; r < rows; ++r)
          for (int l = 0; l < kLanes; ++l)
            REQUIRE(values[static_cast<std::size_t>(r)](l) ==
                    (l < count ? entry(left, right, r, first + l) : S(0)));

        for (auto& v : values) v = random_matrix<S>(kLanes, 1, ++seed, 1.0).array();
        const Matrix<S> left_before = random_matrix<S>(rows, half, ++seed, 1.0);
        const Matrix<S> right_before = random_matrix<S>(rows, half, ++seed, 1.0);
        Matrix<S> left_out = left_before, right_out = right_before;
        Lanes::store_rows(values, first, count, typename Lanes::ColumnsOut{&left_out, &right_out});
        for (Index r = 0; r < rows; ++r) {
          for (Index c = 0; c < 2 * half; ++c) {
            const bool in_block = c >= first && c < first + count;
            REQUIRE(entry(left_out, right_out, r, c) ==
                    (in_block ? values[static_cast<std::size_t>(r)](c - first)
                              : entry(left_before, right_before, r, c)));
          }
        }
      }
    }
  }
}
