// A batch matrix's block of samples into lane arrays and back (sim/lane_rows.hpp): every
// entry against the matrix indexed one entry at a time, for heights that fill no tile, one,
// and several with a partial last one, every count of samples in a block, blocks that start
// past column 0 and blocks that end at the matrix's last column (a read past the block there
// leaves the allocation, for a sanitizer to see); the lanes past the count are 0, and nothing
// outside the block or past the last lane array is written.
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
  for (const Index rows : {1, 2, 5, 7, 8, 9, 15, 16, 17, 24, 28, 33, 40}) {
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
