// The packed product of the layers: against a long-double product with the standard
// floating-point error bound (matrices of at most kLanes/4 rows take the dot-product path; the
// shapes have 1, 2 and 3 rows), a sample's result independent of its batch, untouched padding,
// and Network's packed overloads equal to the plain ones bit for bit.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <tuple>
#include <vector>

#include "support/test_data.hpp"
#include "sbptt/nn/network.hpp"
#include "sbptt/nn/packed_product.hpp"

using sbptt::Index;
using sbptt::Matrix;
using sbptt::PackedMatrix;
using sbptt::testing::random_matrix;
using Catch::Matchers::Contains;

TEMPLATE_TEST_CASE("packed product equals a long-double product within the rounding bound",
                   "[nn][packed]", float, double) {
  using S = TestType;
  const S eps = std::numeric_limits<S>::epsilon();
  std::uint64_t seed = 1;
  for (const auto& [rows, cols] : {std::pair<Index, Index>{1, 1}, {3, 5}, {16, 7}, {17, 33},
                                   {100, 100}, {60, 180}, {33, 2}, {1, 100}}) {
    for (const bool transpose : {false, true}) {
      for (const bool with_bias : {false, true}) {
        for (const Index n : {1, 7, 8, 9, 17, 33}) {
          // The source is row-major `rows × cols`; transposed, A is cols × rows.
          const Matrix<S> source = random_matrix<S>(rows * cols, 1, ++seed, 1.0);
          const Index a_rows = transpose ? cols : rows, a_cols = transpose ? rows : cols;
          const Matrix<S> bias = random_matrix<S>(a_rows, 1, ++seed, 1.0);
          const Matrix<S> x = random_matrix<S>(a_cols, n, ++seed, 1.0);
          PackedMatrix<S> a;
          a.pack(source.data(), rows, cols, transpose, with_bias ? bias.data() : nullptr);
          REQUIRE(a.rows() == a_rows);
          REQUIRE(a.cols() == a_cols);
          Matrix<S> y(a_rows, n);
          a.multiply(x.data(), a_cols, n, y.data(), a_rows);
          for (Index j = 0; j < n; ++j) {
            for (Index i = 0; i < a_rows; ++i) {
              long double exact = with_bias ? bias(i) : 0.0L, magnitude = std::abs(exact);
              for (Index k = 0; k < a_cols; ++k) {
                const S entry = transpose ? source(k * cols + i) : source(i * cols + k);
                exact += static_cast<long double>(entry) * x(k, j);
                magnitude += std::abs(static_cast<long double>(entry) * x(k, j));
              }
              // |fl(Σ) − Σ| ≤ γ_(k+1) Σ|terms| for any order of k fused or unfused additions.
              const long double bound = static_cast<long double>(a_cols + 1) *
                                        static_cast<long double>(eps) * magnitude * 1.01L;
              INFO("rows " << rows << " cols " << cols << " transpose " << transpose << " n "
                           << n << " entry (" << i << ", " << j << ")");
              REQUIRE(std::abs(static_cast<long double>(y(i, j)) - exact) <= bound);
            }
          }
        }
      }
    }
  }
}

// Row counts that reach every way the panels are cut into blocks: 1, 2, 3, 4, 5, 6, 7, 8, 9
// and 11 panels, the last one partial or whole (100 rows: 7 panels of 16 floats, 13 of 8
// doubles), and with AVX-512 every width of a partial last panel: a quarter of a register or
// less, half or less, more than half.
template <class S>
std::vector<Index> panel_row_counts() {
  const Index lanes = PackedMatrix<S>::kLanes;
  // lanes / 2 + 1: one partial panel, more rows than the dot products take.
  // lanes / 2: one panel of half a register; 3 · lanes − lanes / 2: three, the last half.
  // 6 · lanes − 3 · lanes / 4: six, the last a quarter.
  // 4 · lanes − 4: four panels, the last partial (the quantum CNN's 60 rows with AVX-512).
  return {Index{100},         lanes / 2 + 1, lanes / 2,     lanes,
          2 * lanes - 1,      2 * lanes + 1, 3 * lanes,     3 * lanes - lanes / 2,
          4 * lanes - 4,      4 * lanes,     5 * lanes,     6 * lanes - 3 * lanes / 4,
          7 * lanes - 5,      8 * lanes - 1, 9 * lanes - 3, 10 * lanes + 1};
}

TEMPLATE_TEST_CASE("a column's result does not depend on the batch around it", "[nn][packed]",
                   float, double) {
  using S = TestType;
  // 100 rows use the panels, kLanes/4 rows (if a register has 4 lanes or more) and 1 row the
  // short-matrix dot products (file comment). In panels, every batch of 1 to 19 columns cuts
  // into blocks of 8, 4, 2 and 1 columns, and the panels (1, 2, 3, 4, 5, 7, 8, 9 and 11 of
  // them, the last partial or whole) into blocks of 1, 2, 3 and up to 8: a column must come
  // out the same in each.
  std::vector<Index> row_counts = panel_row_counts<S>();
  row_counts.push_back(std::max<Index>(1, PackedMatrix<S>::kLanes / 4));
  row_counts.push_back(1);
  for (const Index rows : row_counts) {
    const Matrix<S> w = random_matrix<S>(rows * 37, 1, 5, 1.0);
    const Matrix<S> b = random_matrix<S>(rows, 1, 6, 1.0);
    PackedMatrix<S> a;
    a.pack(w.data(), rows, 37, false, b.data());
    const Matrix<S> x = random_matrix<S>(37, 19, 7, 1.0);
    Matrix<S> single(rows, 1);
    for (Index n = 1; n <= 19; ++n) {
      Matrix<S> batch(rows, n);
      a.multiply(x.data(), 37, n, batch.data(), rows);
      for (Index j = 0; j < n; ++j) {
        a.multiply(x.col(j).data(), 37, 1, single.data(), rows);
        INFO("rows " << rows << ", column " << j << " of " << n);
        REQUIRE((single.col(0).array() == batch.col(j).array()).all());
      }
    }
  }
}

TEMPLATE_TEST_CASE("every entry of the product is its bias plus the terms in column order",
                   "[nn][packed]", float, double) {
  // The order of the file comment, with fused multiply-adds where the build has them: one
  // independent truth for every block shape at once (the batch test above only ties them).
  // A packed from W (rows × cols, row-major) and from the transpose of W (cols × rows), whose
  // panels are copied by different code.
  using S = TestType;
  for (const Index rows : panel_row_counts<S>()) {
    for (const bool transpose : {false, true}) {
      const Index cols = 29;
      const Matrix<S> w = random_matrix<S>(rows * cols, 1, 15, 1.0);
      const Matrix<S> b = random_matrix<S>(rows, 1, 16, 1.0);
      const auto entry = [&](Index i, Index k) {
        return transpose ? w(k * rows + i) : w(i * cols + k);
      };
      PackedMatrix<S> a;
      a.pack(w.data(), transpose ? cols : rows, transpose ? rows : cols, transpose, b.data());
      for (const Index n :
           {Index{1}, Index{2}, Index{3}, Index{4}, Index{7}, Index{8}, Index{13}}) {
        const Matrix<S> x = random_matrix<S>(cols, n, static_cast<std::uint64_t>(17 + n), 1.0);
        // NaN until written: an entry that no block computes cannot pass.
        Matrix<S> y = Matrix<S>::Constant(rows, n, std::numeric_limits<S>::quiet_NaN());
        a.multiply(x.data(), cols, n, y.data(), rows);
        for (Index j = 0; j < n; ++j) {
          for (Index i = 0; i < rows; ++i) {
            S sum = b(i);
            for (Index k = 0; k < cols; ++k)
              sum = sbptt::detail::fused_multiply_add(entry(i, k), x(k, j), sum);
            INFO("rows " << rows << " transpose " << transpose << " n " << n << " entry (" << i
                         << ", " << j << ")");
            REQUIRE(y(i, j) == sum);
          }
        }
      }
    }
  }
}

TEMPLATE_TEST_CASE("a short matrix's entries are the file comment's dot products, bit for bit",
                   "[nn][packed]", float, double) {
  // Lane-wise partial sums over whole registers, reduced by Eigen's predux, added to the bias,
  // then the remaining terms in order: written here one entry at a time, against the
  // products' dot products side by side, for every short row count and batches of 1 to 19
  // (whole groups of columns and every remainder), at leading dimensions past the matrices.
  using S = TestType;
  using Packet = typename Eigen::internal::packet_traits<S>::type;
  const Index lanes = PackedMatrix<S>::kLanes;
  for (Index rows = 1; 4 * rows <= lanes; ++rows) {
    for (const Index cols : {Index{5}, Index{37}, Index{100}}) {
      const Matrix<S> w =
          random_matrix<S>(rows * cols, 1, static_cast<std::uint64_t>(21 + cols), 1.0);
      const Matrix<S> b = random_matrix<S>(rows, 1, 22, 1.0);
      PackedMatrix<S> a;
      a.pack(w.data(), rows, cols, false, b.data());
      // Leading dimensions past the matrices: ldx = cols + 3, ldy = rows + 2.
      const Matrix<S> x = random_matrix<S>(cols + 3, 19, 23, 1.0);
      const Index whole = cols / lanes * lanes;
      for (Index n = 1; n <= 19; ++n) {
        Matrix<S> y = Matrix<S>::Constant(rows + 2, n, std::numeric_limits<S>::quiet_NaN());
        a.multiply(x.data(), cols + 3, n, y.data(), rows + 2);
        REQUIRE(y.bottomRows(2).array().isNaN().all());
        for (Index j = 0; j < n; ++j) {
          for (Index i = 0; i < rows; ++i) {
            S sum = b(i);
            if (whole > 0) {
              Packet acc = Eigen::internal::pset1<Packet>(S(0));
              for (Index k = 0; k < whole; k += lanes)
                acc = Eigen::internal::pmadd(Eigen::internal::ploadu<Packet>(&w(i * cols + k)),
                                             Eigen::internal::ploadu<Packet>(&x(k, j)), acc);
              sum += Eigen::internal::predux(acc);
            }
            for (Index k = whole; k < cols; ++k)
              sum = sbptt::detail::fused_multiply_add(w(i * cols + k), x(k, j), sum);
            INFO("rows " << rows << " cols " << cols << " n " << n << " entry (" << i << ", "
                         << j << ")");
            REQUIRE(y(i, j) == sum);
          }
        }
      }
    }
  }
}

TEMPLATE_TEST_CASE("with tanh outputs T, each entry is the product's times 1 − T²",
                   "[nn][packed]", float, double) {
  // The backward pass's Wᵀ Δ ⊙ (1 − T²) in one call: against the plain product times 1 − t²
  // in long double, whose rounding (t², 1 − t², the product: three) is bounded by
  // 3 eps |y| (1 + t²); for panels and short matrices, every block width of 1 to 13 columns,
  // a column independent of its batch, and at leading dimensions past the rows, whose entries
  // of T (NaN) are not read and of Y not written.
  using S = TestType;
  const S eps = std::numeric_limits<S>::epsilon();
  std::vector<Index> row_counts = panel_row_counts<S>();
  row_counts.push_back(std::max<Index>(1, PackedMatrix<S>::kLanes / 4));
  row_counts.push_back(1);
  const S nan = std::numeric_limits<S>::quiet_NaN();
  for (const Index rows : row_counts) {
    const Index cols = 23, ld = rows + 3;
    const Matrix<S> w = random_matrix<S>(rows * cols, 1, 31, 1.0);
    PackedMatrix<S> a;
    a.pack(w.data(), cols, rows, true);  // a Wᵀ, as the backward pass packs it
    const Matrix<S> x = random_matrix<S>(cols, 13, 32, 1.0);
    Matrix<S> t = Matrix<S>::Constant(ld, 13, nan);
    t.topRows(rows) = random_matrix<S>(rows, 13, 33, 1.0).array().tanh().matrix();
    Matrix<S> plain(rows, 13), single = Matrix<S>::Constant(ld, 1, S(7.25));
    a.multiply(x.data(), cols, 13, plain.data(), rows);
    for (Index n = 1; n <= 13; ++n) {
      Matrix<S> y = Matrix<S>::Constant(ld, n, S(7.25));
      a.multiply(x.data(), cols, n, y.data(), ld, t.data());
      REQUIRE((y.bottomRows(3).array() == S(7.25)).all());
      for (Index j = 0; j < n; ++j) {
        a.multiply(x.col(j).data(), cols, 1, single.data(), ld, t.col(j).data());
        INFO("rows " << rows << ", column " << j << " of " << n);
        REQUIRE((single.col(0).array() == y.col(j).array()).all());
        for (Index i = 0; i < rows; ++i) {
          const long double tt = static_cast<long double>(t(i, j)) * t(i, j);
          const long double exact = static_cast<long double>(plain(i, j)) * (1.0L - tt);
          const long double bound =
              3.03L * static_cast<long double>(eps) * std::abs(plain(i, j)) * (1.0L + tt);
          INFO("entry " << i);
          REQUIRE(std::abs(static_cast<long double>(y(i, j)) - exact) <= bound);
        }
      }
    }
  }
}

TEMPLATE_TEST_CASE("the product writes the real rows only, at the given leading dimensions",
                   "[nn][packed]", float, double) {
  // 19 rows: the last panel is padded (a masked store with AVX-512, a buffer elsewhere); ldy =
  // 23 leaves 4 rows of every column untouched.
  using S = TestType;
  const S tolerance = 64 * std::numeric_limits<S>::epsilon();
  const Matrix<S> w = random_matrix<S>(Index{19} * 5, 1, 8, 1.0);
  PackedMatrix<S> a;
  a.pack(w.data(), 19, 5, false);
  const Matrix<S> x = random_matrix<S>(9, 11, 9, 1.0);  // ldx 9 > cols 5
  Matrix<S> y = Matrix<S>::Constant(23, 11, S(7.25));
  a.multiply(x.data(), 9, 11, y.data(), 23);
  const Eigen::Map<const sbptt::RowMajorMatrix<S>> wm(w.data(), 19, 5);
  const Matrix<S> expected = wm * x.topRows(5);
  REQUIRE((y.topRows(19) - expected).cwiseAbs().maxCoeff() <= tolerance);
  REQUIRE((y.bottomRows(4).array() == S(7.25)).all());
  // A short matrix (1 row, dot products) at ldy 3: rows 1 and 2 of every column untouched.
  PackedMatrix<S> row;
  row.pack(w.data(), 1, 5, false);
  Matrix<S> y1 = Matrix<S>::Constant(3, 11, S(7.25));
  row.multiply(x.data(), 9, 11, y1.data(), 3);
  REQUIRE((y1.row(0) - wm.row(0) * x.topRows(5)).cwiseAbs().maxCoeff() <= tolerance);
  REQUIRE((y1.bottomRows(2).array() == S(7.25)).all());
}

// The engine calls the packed overloads, the finite-difference tests the plain ones: this ties
// the two (a stale or mis-indexed packing, a dropped bias would show here).
TEMPLATE_TEST_CASE("Network's packed overloads equal the plain ones bit for bit", "[nn][packed]",
                   float, double) {
  using S = TestType;
  using sbptt::Activation;
  sbptt::Network<S> net({sbptt::Conv1d{32, 2, 20, 3, 2, Activation::Tanh},
                         sbptt::Conv1d{15, 20, 12, 3, 2, Activation::Tanh},
                         sbptt::Dense{84, 17, Activation::Tanh}, sbptt::Dense{17, 3}});
  sbptt::testing::randomize(net, 11, 0.5);
  const Matrix<S> x = random_matrix<S>(64, 9, 12, 1.0), dy = random_matrix<S>(3, 9, 13, 1.0);
  typename sbptt::Network<S>::PackedWeights packed;
  net.pack(packed);
  typename sbptt::Network<S>::Workspace plain_ws, packed_ws;
  Matrix<S> plain_y, packed_y, plain_dx, packed_dx;
  net.forward(x, plain_y, plain_ws);
  net.forward(x, packed_y, packed_ws, packed);
  REQUIRE((plain_y.array() == packed_y.array()).all());
  sbptt::Vector<S> plain_grad = sbptt::Vector<S>::Zero(net.num_params());
  sbptt::Vector<S> packed_grad = plain_grad;
  net.backward(plain_ws, dy, plain_grad, &plain_dx);
  net.backward(packed_ws, dy, packed_grad, &packed_dx, packed);
  REQUIRE((plain_grad.array() == packed_grad.array()).all());
  REQUIRE((plain_dx.array() == packed_dx.array()).all());
}

TEST_CASE("packed weights of another shape are refused before any product", "[nn][packed]") {
  const auto small = sbptt::Network<double>::mlp(3, {4}, 2);
  const auto large = sbptt::Network<double>::mlp(3, {5}, 2);
  // Same number of weights (24), transposed shapes: a count check would let the product
  // write 6 rows into a 4-row output.
  const sbptt::Network<double> wide({sbptt::Dense{4, 6}}), tall({sbptt::Dense{6, 4}});
  sbptt::Network<double>::PackedWeights packed, none, packed_wide;
  large.pack(packed);
  wide.pack(packed_wide);
  sbptt::Network<double>::Workspace ws;
  Matrix<double> y;
  const auto refused = Contains("expected weights packed by pack() of this network");
  REQUIRE_THROWS_WITH(small.forward(Matrix<double>::Zero(3, 2), y, ws, packed), refused);
  REQUIRE_THROWS_WITH(small.forward(Matrix<double>::Zero(3, 2), y, ws, none), refused);
  REQUIRE_THROWS_WITH(tall.forward(Matrix<double>::Zero(6, 2), y, ws, packed_wide), refused);
  tall.forward(Matrix<double>::Zero(6, 2), y, ws);
  sbptt::Vector<double> grad = sbptt::Vector<double>::Zero(tall.num_params());
  Matrix<double> dx;
  REQUIRE_THROWS_WITH(tall.backward(ws, Matrix<double>::Zero(4, 2), grad, &dx, packed_wide),
                      refused);
}
