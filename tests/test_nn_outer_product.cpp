// dW += D Xᵀ, the layers' parameter product: against a long-double product with the standard
// floating-point error bound, over shapes that reach every branch of the AVX-512 kernel (full
// and masked column panels, row and sample remainders) and of the AVX2 one (2-panel blocks,
// single and half panels, single columns, rows left after blocks of 6, chunks of 64 samples),
// and nothing written outside dW.
#include <catch2/catch.hpp>

#include <cmath>
#include <limits>
#include <tuple>
#include <utility>
#include <vector>

#include "support/test_data.hpp"
#include "sbptt/nn/outer_product.hpp"

using sbptt::Index;
using sbptt::Matrix;
using sbptt::testing::random_matrix;

TEMPLATE_TEST_CASE("dW += D X^T within the rounding bound, nothing written outside dW",
                   "[nn][outer]", float, double) {
  using S = TestType;
  const S eps = std::numeric_limits<S>::epsilon();
  // Sentinels before and after dW: a masked store must stop at the end of the row.
  constexpr Index kGuard = 64;
  constexpr S kSentinel = S(-7.5);
  std::uint64_t seed = 100;
  // cols (float panels of 16): below one register, one register of either type, 3 panels and
  // a masked one (53), 5 panels (a block of 3 and one of 2), 100 (6 + 4), the
  // convolution's 180 (3 blocks, then 2 and 4 masked as one block); 21 and 37 (one or two whole
  // panels and a masked one, starting the row); 41 (the same in double after a block of 3);
  // rows: 1, 2, odd, the paper's 100. Rows narrower than a register go one at a time in passes
  // of every 2nd (17 × 10 float, 19 × 5 double), 3rd (21 × 6 float) or 8th row (23 × 2
  // float); rows of one entry go to Eigen (30 × 1). A quarter of a register after whole panels
  // or alone (100 and 52 in float, 26 and 2 in double; quarter_strip.hpp) goes 4 rows a register,
  // the last 1 … 3 rows on their own (17 × 52, 6 × 26, 3 × 100, 23 × 2). Half a register
  // after 1 or 2 whole panels, starting the row or after a block of 3 (float 24, 40, 72, 88;
  // double 12, 20, 44), goes by half-width instructions.
  for (const auto& [rows, cols] :
       {std::pair<Index, Index>{1, 100}, {2, 100}, {3, 10}, {5, 8}, {7, 16}, {100, 100},
        {100, 24}, {60, 180}, {17, 53}, {33, 64}, {9, 80}, {17, 10}, {19, 5}, {21, 4}, {21, 6},
        {23, 2}, {30, 1}, {18, 37}, {18, 21}, {9, 41}, {17, 52}, {6, 26}, {3, 100},
        {13, 40}, {7, 72}, {9, 88}, {5, 12}, {6, 20}, {4, 44}}) {
    for (const Index n : {1, 3, 7, 8, 9, 16, 21, 56, 70}) {
      const Matrix<S> d = random_matrix<S>(rows, n, ++seed, 1.0);
      const Matrix<S> x = random_matrix<S>(cols, n, ++seed, 1.0);
      const Matrix<S> start = random_matrix<S>(rows * cols, 1, ++seed, 1.0);
      sbptt::Vector<S> buffer = sbptt::Vector<S>::Constant(rows * cols + 2 * kGuard, kSentinel);
      buffer.segment(kGuard, rows * cols) = start;
      sbptt::add_outer_products(buffer.data() + kGuard, rows, cols, d.data(), x.data(), n);
      INFO("rows " << rows << " cols " << cols << " n " << n);
      REQUIRE((buffer.head(kGuard).array() == kSentinel).all());
      REQUIRE((buffer.tail(kGuard).array() == kSentinel).all());
      for (Index i = 0; i < rows; ++i) {
        for (Index j = 0; j < cols; ++j) {
          long double exact = start(i * cols + j), magnitude = std::abs(exact);
          for (Index k = 0; k < n; ++k) {
            const long double term = static_cast<long double>(d(i, k)) * x(j, k);
            exact += term;
            magnitude += std::abs(term);
          }
          // |fl(Σ) − Σ| ≤ γ_(n+1) Σ|terms| for any order of n fused or unfused additions.
          const long double bound =
              static_cast<long double>(n + 1) * static_cast<long double>(eps) * magnitude * 1.01L;
          INFO("entry (" << i << ", " << j << ")");
          REQUIRE(std::abs(static_cast<long double>(buffer(kGuard + i * cols + j)) - exact) <=
                  bound);
        }
      }
    }
  }
}

TEMPLATE_TEST_CASE("dW += D diag(s) X^T: the kernel's scale within the rounding bound",
                   "[nn][outer]", float, double) {
  // The scale multiplies a block of X once for all rows: each term is d·(s·x), one rounding
  // more.
  using S = TestType;
  const S eps = std::numeric_limits<S>::epsilon();
  std::uint64_t seed = 500;
  int kernel_cases = 0;
  for (const auto& [rows, cols] : {std::pair<Index, Index>{100, 10}, {100, 100}, {1, 100},
                                   {60, 180}, {17, 53}, {19, 5}, {19, 3}, {40, 1}}) {
    for (const Index n : {1, 7, 8, 16, 21, 70}) {
      const Matrix<S> d = random_matrix<S>(rows, n, ++seed, 1.0);
      const Matrix<S> x = random_matrix<S>(cols, n, ++seed, 1.0);
      const Matrix<S> scale = random_matrix<S>(n, 1, ++seed, 3.0);
      sbptt::Vector<S> dw = random_matrix<S>(rows * cols, 1, ++seed, 1.0);
      const sbptt::Vector<S> start = dw;
      INFO("rows " << rows << " cols " << cols << " n " << n);
      if (!sbptt::outer_product_kernel_applies<S>(cols)) {
        // Eigen's product takes no scale: refused, and nothing written.
        CHECK_THROWS_WITH(sbptt::add_outer_products(dw.data(), rows, cols, d.data(), x.data(), n,
                                                    scale.data()),
                          Catch::Contains("a scale for rows of"));
        CHECK(dw == start);
        continue;
      }
      sbptt::add_outer_products(dw.data(), rows, cols, d.data(), x.data(), n, scale.data());
      ++kernel_cases;
      for (Index i = 0; i < rows; ++i) {
        for (Index j = 0; j < cols; ++j) {
          long double exact = start(i * cols + j), magnitude = std::abs(exact);
          for (Index k = 0; k < n; ++k) {
            const long double term =
                static_cast<long double>(d(i, k)) * scale(k) * static_cast<long double>(x(j, k));
            exact += term;
            magnitude += std::abs(term);
          }
          const long double bound =
              static_cast<long double>(n + 2) * static_cast<long double>(eps) * magnitude * 1.01L;
          INFO("entry (" << i << ", " << j << ")");
          REQUIRE(std::abs(static_cast<long double>(dw(i * cols + j)) - exact) <= bound);
        }
      }
    }
  }
  // Where a kernel exists at all (AVX-512, or AVX2 with FMA), these shapes must have reached it.
  if (sbptt::outer_product_kernel_applies<S>(1 << 20)) CHECK(kernel_cases > 0);
}

TEMPLATE_TEST_CASE("dW += D diag(s) X^T: the kernel sums each entry in sample order, bit for bit",
                   "[nn][outer]", float, double) {
  // The kernel's promise (outer_product.hpp): every entry is ((dW_ij + d_i0 x'_j0) + d_i1
  // x'_j1) + … with fused multiply-adds, x' = s·x rounded, whatever the shapes and whatever
  // order the kernel visits the rows in (passes of every 2nd … 8th row where a masked panel's
  // block starts the row). Rows narrower than a register (1 … 17 rows, the paper's 100 × 10,
  // an odd 97, 2 and 3 entries); a partial panel in one block with 1 or 2 whole panels,
  // starting the row or after blocks of 3; alone after them (100 × 100); the convolution's
  // 60 × 180; a quarter of a register's columns after 1 … 6 whole panels, or alone 4 rows a
  // register (quarter_strip.hpp); half a register after 0 … 2 whole panels, starting the row
  // or after a block of 3 (half-width instructions with AVX-512). 70 samples: the AVX2 kernel
  // scales X in chunks of 64.
  using S = TestType;
  constexpr Index kLanes = sizeof(S) == 4 ? 16 : 8;
  std::uint64_t seed = 900;
  int kernel_cases = 0;
  std::vector<std::pair<Index, Index>> shapes = {
      {100, kLanes / 2 + 2}, {97, kLanes - 1},     {33, kLanes + 3}, {18, 2 * kLanes + 5},
      {9, 5 * kLanes + 1},   {11, 4 * kLanes + 7}, {100, 100},       {60, 180},
      {100, 24},             {100, 2},             {41, 3},          {23, kLanes / 2 - 1},
      {17, 3 * kLanes + 5},  {29, kLanes / 4},     {5, 2},           {7, kLanes},
      {5, 2 * kLanes},       {6, kLanes + kLanes / 2}, {13, 2 * kLanes + kLanes / 2},
      {19, 3 * kLanes + kLanes / 2}, {7, 4 * kLanes + kLanes / 2}, {9, 5 * kLanes + kLanes / 2}};
  for (Index rows = 1; rows <= 17; ++rows) shapes.emplace_back(rows, kLanes / 2);
  // A quarter of a register left after 1 … 6 whole panels, in a block with up to two of them
  // (blocks of 2 rows and a row left), or alone (quarter_strip.hpp: 4 rows a register and the
  // last 1 … 3 rows on their own).
  for (Index rows = 1; rows <= 9; ++rows) {
    for (Index whole = 1; whole <= 6; ++whole)
      shapes.emplace_back(rows, whole * kLanes + kLanes / 4);
    shapes.emplace_back(rows, kLanes / 4);
  }
  for (const auto& [rows, cols] : shapes) {
    if (!sbptt::outer_product_kernel_applies<S>(cols)) continue;
    for (const Index n : {1, 8, 9, 21, 70}) {
      for (const bool scaled : {false, true}) {
        ++kernel_cases;
        const Matrix<S> d = random_matrix<S>(rows, n, ++seed, 1.0);
        const Matrix<S> x = random_matrix<S>(cols, n, ++seed, 1.0);
        const Matrix<S> scale = random_matrix<S>(n, 1, ++seed, 3.0);
        sbptt::Vector<S> dw = random_matrix<S>(rows * cols, 1, ++seed, 1.0);
        const sbptt::Vector<S> start = dw;
        sbptt::add_outer_products(dw.data(), rows, cols, d.data(), x.data(), n,
                                  scaled ? scale.data() : nullptr);
        INFO("rows " << rows << " cols " << cols << " n " << n << " scaled " << scaled);
        for (Index i = 0; i < rows; ++i) {
          for (Index j = 0; j < cols; ++j) {
            S expected = start(i * cols + j);
            for (Index k = 0; k < n; ++k) {
              const S xs = scaled ? S(x(j, k) * scale(k)) : x(j, k);
              expected = std::fma(xs, d(i, k), expected);
            }
            INFO("entry (" << i << ", " << j << ")");
            REQUIRE(dw(i * cols + j) == expected);
          }
        }
      }
    }
  }
  // Where a kernel exists at all (AVX-512, or AVX2 with FMA), these shapes must have reached it.
  if (sbptt::outer_product_kernel_applies<S>(1 << 20)) CHECK(kernel_cases > 0);
}

TEMPLATE_TEST_CASE("db += D s: each bias entry summed in sample order, bit for bit, nothing "
                   "written past the bias", "[nn][outer]", float, double) {
  // outer_product.hpp's promise for the bias: ((b_i + d_i0 s_0) + d_i1 s_1) + …, fused with a
  // scale, whatever the rows: whole blocks of registers, the registers left, a masked last
  // one, rows within one register. The scale exists only where the register kernel runs.
  using S = TestType;
  constexpr Index kGuard = 32;
  constexpr S kSentinel = S(-7.5);
  constexpr Index cols = 24;
  std::uint64_t seed = 1700;
  std::vector<Index> row_counts = {100, 128, 129};
  for (Index rows = 1; rows <= 70; ++rows) row_counts.push_back(rows);
  for (const Index rows : row_counts) {
    for (const Index n : {1, 8, 9, 120}) {
      for (const bool scaled : {false, true}) {
        if (scaled && !sbptt::outer_product_kernel_applies<S>(cols)) continue;
        const Matrix<S> d = random_matrix<S>(rows, n, ++seed, 1.0);
        const Matrix<S> x = random_matrix<S>(cols, n, ++seed, 1.0);
        const Matrix<S> scale = random_matrix<S>(n, 1, ++seed, 3.0);
        const Matrix<S> start = random_matrix<S>(rows, 1, ++seed, 1.0);
        sbptt::Vector<S> grad = sbptt::Vector<S>::Constant(rows * cols + rows + kGuard, kSentinel);
        grad.segment(rows * cols, rows) = start;
        sbptt::add_weight_and_bias_products(grad.data(), rows, cols, d.data(), x.data(), n,
                                            scaled ? scale.data() : nullptr);
        INFO("rows " << rows << " n " << n << " scaled " << scaled);
        REQUIRE((grad.tail(kGuard).array() == kSentinel).all());
        for (Index i = 0; i < rows; ++i) {
          S expected = start(i);
          for (Index k = 0; k < n; ++k)
            expected = scaled ? std::fma(d(i, k), scale(k), expected) : expected + d(i, k);
          INFO("bias entry " << i);
          CHECK(grad(rows * cols + i) == expected);
        }
      }
    }
  }
}
