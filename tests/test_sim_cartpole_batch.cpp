// CartPole's batched step and vjp (float and double samples in SIMD lanes): against the
// per-sample step and vjp, the float ones against the analytic Jacobians in double (themselves
// checked against finite differences in test_sim_cartpole.cpp) and against central differences
// of the batched step itself; independence from the other columns, for the reference and the
// physical model; the lane layouts of the reference model against each other.
#include <catch2/catch.hpp>

#include <cmath>
#include <limits>
#include <numbers>
#include <type_traits>

#include "sbptt/core/rng.hpp"
#include "sbptt/sim/cartpole.hpp"
#include "support/batch_simulator.hpp"

namespace {

using sbptt::CartPole;
using sbptt::CartPoleModel;
using sbptt::CartPoleOptions;
using sbptt::Index;
using sbptt::Matrix;

template <class Scalar = float>
struct Batch {
  Matrix<Scalar> x, u, lambda;
};

// States of the paper's distribution spread to any angle (poles upright, hanging and spun
// past 2π), forces in ±20 N, cotangents.
template <class Scalar = float>
Batch<Scalar> random_batch(Index state_dim, Index size, sbptt::Rng& rng) {
  Batch<Scalar> b{Matrix<Scalar>(state_dim, size), Matrix<Scalar>(1, size),
                  Matrix<Scalar>(state_dim, size)};
  for (Index c = 0; c < size; ++c) {
    for (Index i = 0; i < state_dim; ++i) {
      const bool angle = i >= 2 && i % 2 == 0;
      b.x(i, c) = static_cast<Scalar>(angle ? rng.uniform(-3.0, 3.0) * std::numbers::pi
                                            : rng.uniform(-2.0, 2.0));
      b.lambda(i, c) = static_cast<Scalar>(rng.normal());
    }
    b.u(0, c) = static_cast<Scalar>(rng.uniform(-20.0, 20.0));
  }
  return b;
}

CartPoleOptions physical() {
  CartPoleOptions options;
  options.model = CartPoleModel::Physical;
  return options;
}

// Both in the simulator's scalar: a few roundings of the sine and cosine apart.
template <class Sim>
void check_against_per_sample(const Sim& sim, Index size, sbptt::Rng& rng) {
  using Scalar = typename Sim::Scalar;
  const auto b = random_batch<Scalar>(sim.state_dim(), size, rng);
  INFO(sim.poles() << " poles");
  const double tolerance = std::is_same_v<Scalar, float> ? 2e-6 : 4e-15;
  sbptt::testing::check_matches_per_sample(sim, b.x, b.u, b.lambda, tolerance);
}

// Aᵀλ and Bᵀλ of float vjp_batch against the analytic Jacobians of the double model at the same
// (float) point.
template <int Poles>
void check_against_double_jacobians(const CartPoleOptions& options, sbptt::Rng& rng) {
  const CartPole<float, Poles> sim(options);
  const CartPole<double, Poles> reference(options);
  const Batch<float> b = random_batch(sim.state_dim(), 19, rng);
  Matrix<float> lambda_x, lambda_u;
  sim.vjp_batch(b.x, b.u, b.lambda, &lambda_x, &lambda_u);
  for (Index c = 0; c < b.x.cols(); ++c) {
    typename CartPole<double, Poles>::StateJacobian a;
    typename CartPole<double, Poles>::ControlJacobian control;
    const typename CartPole<double, Poles>::State x = b.x.col(c).cast<double>();
    const typename CartPole<double, Poles>::State lambda = b.lambda.col(c).cast<double>();
    reference.jacobians(x, typename CartPole<double, Poles>::Control(b.u(0, c)), a, control);
    const Eigen::VectorXd expected_x = a.transpose() * lambda;
    const double expected_u = control.dot(lambda);
    INFO("column " << c);
    CHECK((lambda_x.col(c).cast<double>() - expected_x).norm() < 1e-5 * (1 + expected_x.norm()));
    CHECK(std::abs(lambda_u(0, c) - expected_u) < 1e-5 * (1 + std::abs(expected_u)));
  }
}

}  // namespace

TEST_CASE("cartpole batch: step_batch and vjp_batch equal step and vjp per column",
          "[sim][cartpole]") {
  sbptt::Rng rng(41);
  for (Index size : {1, 7, 8, 16, 19, 40}) {
    check_against_per_sample(CartPole<float, 4>(), size, rng);
    check_against_per_sample(CartPole<float, Eigen::Dynamic>(3), size, rng);
    check_against_per_sample(CartPole<float, 2>(physical()), size, rng);
    check_against_per_sample(CartPole<double, 4>(), size, rng);
    check_against_per_sample(CartPole<double, Eigen::Dynamic>(3), size, rng);
    check_against_per_sample(CartPole<double, 2>(physical()), size, rng);
  }
  check_against_per_sample(CartPole<float, 1>(), 5, rng);
  check_against_per_sample(CartPole<double, 1>(), 5, rng);
}

TEST_CASE("cartpole batch: the per-column comparison reports a NaN column as NaN",
          "[sim][cartpole]") {
  // A batched step that writes NaN into one column past the first: the running worst over the
  // columns must keep it (std::max(worst, NaN) keeps worst).
  struct NanColumn : CartPole<float, 2> {
    void step_batch(const Matrix<float>& x, const Matrix<float>& u, Matrix<float>& next) const {
      CartPole<float, 2>::step_batch(x, u, next);
      next(0, 3) = std::numeric_limits<float>::quiet_NaN();
    }
  };
  sbptt::Rng rng(5);
  const Batch<float> b = random_batch(NanColumn().state_dim(), 8, rng);
  const auto errors = sbptt::testing::per_sample_errors(NanColumn(), b.x, b.u, b.lambda);
  CHECK(std::isnan(errors.step));
  CHECK(errors.state < 2e-6);
}

TEST_CASE("cartpole batch: vjp_batch equals the analytic Jacobians' products in double",
          "[sim][cartpole]") {
  sbptt::Rng rng(42);
  check_against_double_jacobians<4>({}, rng);
  check_against_double_jacobians<1>({}, rng);
  check_against_double_jacobians<3>(physical(), rng);
}

TEST_CASE("cartpole batch: vjp_batch matches central differences of step_batch",
          "[sim][cartpole]") {
  // ⟨λ, (P(x + εv, u + εw) − P(x − εv, u − εw)) / 2ε⟩ = ⟨Aᵀλ, v⟩ + (Bᵀλ)·w, per column, in
  // float: ε = 1e-2 keeps the rounding of the difference near 1e-5, and the truncation,
  // O(ε²·dt) for this near-identity map, below it.
  for (const CartPoleOptions& options : {CartPoleOptions{}, physical()}) {
    const CartPole<float, 3> sim(options);
    sbptt::Rng rng(43);
    const Index size = 21;
    const Batch<float> b = random_batch(sim.state_dim(), size, rng);
    const Batch<float> direction = random_batch(sim.state_dim(), size, rng);
    Matrix<float> lambda_x, lambda_u, plus, minus;
    sim.vjp_batch(b.x, b.u, b.lambda, &lambda_x, &lambda_u);
    const float eps = 1e-2F;
    const Matrix<float> w = direction.u / 20.0F;
    const Matrix<float> v = direction.x / 4.0F;
    sim.step_batch(b.x + eps * v, b.u + eps * w, plus);
    sim.step_batch(b.x - eps * v, b.u - eps * w, minus);
    for (Index c = 0; c < size; ++c) {
      const double difference =
          b.lambda.col(c).cast<double>().dot((plus.col(c) - minus.col(c)).cast<double>()) /
          (2.0 * eps);
      const double adjoint = lambda_x.col(c).cast<double>().dot(v.col(c).cast<double>()) +
                             static_cast<double>(lambda_u(0, c)) * w(0, c);
      INFO("model " << static_cast<int>(options.model) << ", column " << c);
      CHECK(std::abs(difference - adjoint) < 2e-3 * (1 + std::abs(adjoint)));
    }
  }
}

TEMPLATE_TEST_CASE("cartpole batch: a column's result does not depend on the other columns",
                   "[sim][cartpole]", float, double) {
  const CartPole<TestType, 4> sim;
  sbptt::Rng rng(44);
  const auto b = random_batch<TestType>(sim.state_dim(), 21, rng);
  sbptt::testing::check_columns_independent(sim, b.x, b.u, b.lambda);
  sbptt::testing::check_columns_independent(CartPole<TestType, 4>(physical()), b.x, b.u,
                                            b.lambda);
  Matrix<TestType> lambda_x, lambda_u, only_u;  // lambda_x may be skipped
  sim.vjp_batch(b.x, b.u, b.lambda, &lambda_x, &lambda_u);
  sim.vjp_batch(b.x, b.u, b.lambda, nullptr, &only_u);
  CHECK(only_u == lambda_u);
}

TEMPLATE_TEST_CASE("cartpole batch: a lane per pole and sample gives the lane per sample's "
                   "numbers", "[sim][cartpole]", float, double) {
  // Fewer samples than a block (16 floats, 8 doubles) take a lane per pole and sample when that
  // needs fewer passes (4 samples of 4 poles in floats: one); a full block keeps a lane per
  // sample. Samples taken from both ends of a full block must give, bit for bit, what they
  // give in it, whether they form a batch of their own or follow a full block in a longer
  // batch (so that the short block starts at the second block). Pole counts that fit from 16
  // samples to 1 in a block, and ones that fit none; with 1 pole the lane per sample is
  // always taken.
  constexpr Index block = sbptt::detail::LaneRows<TestType>::kLanes;
  for (const Index poles : {1, 2, 3, 4, 5, 8, 9, 12, 16, 17}) {
    const CartPole<TestType, Eigen::Dynamic> sim(poles);
    sbptt::Rng rng(45);
    const auto b = random_batch<TestType>(sim.state_dim(), block, rng);
    Matrix<TestType> next, lambda_x, lambda_u;
    sim.step_batch(b.x, b.u, next);
    sim.vjp_batch(b.x, b.u, b.lambda, &lambda_x, &lambda_u);
    for (const Index count : {1, 2, 3, 4, 5, 7, 8, 9, 12, 15}) {
      if (count >= block) continue;
      for (const Index first : {Index{0}, block - count}) {
        for (const Index behind : {Index{0}, block}) {  // columns before the samples
          Matrix<TestType> x(sim.state_dim(), behind + count), u(1, behind + count);
          Matrix<TestType> lambda(sim.state_dim(), behind + count);
          x << b.x.leftCols(behind), b.x.middleCols(first, count);
          u << b.u.leftCols(behind), b.u.middleCols(first, count);
          lambda << b.lambda.leftCols(behind), b.lambda.middleCols(first, count);
          Matrix<TestType> part_next, part_x, part_u;
          sim.step_batch(x, u, part_next);
          sim.vjp_batch(x, u, lambda, &part_x, &part_u);
          INFO(poles << " poles, samples " << first << " … " << first + count - 1 << " after "
                     << behind << " columns");
          CHECK(part_next.rightCols(count) == next.middleCols(first, count));
          CHECK(part_x.rightCols(count) == lambda_x.middleCols(first, count));
          CHECK(part_u.rightCols(count) == lambda_u.middleCols(first, count));
        }
      }
    }
  }
}

TEST_CASE("cartpole batch: bad shapes are rejected with a message", "[sim][cartpole]") {
  const CartPole<float, 2> sim;
  Matrix<float> out;
  const Matrix<float> x = Matrix<float>::Zero(6, 4), u = Matrix<float>::Zero(1, 4);
  CHECK_THROWS_WITH(sim.step_batch(Matrix<float>::Zero(5, 4), u, out),
                    Catch::Contains("x has 5 rows; expected state_dim() = 6"));
  CHECK_THROWS_WITH(sim.step_batch(x, Matrix<float>::Zero(1, 3), out),
                    Catch::Contains("u is 1 x 3; expected 1 x 4"));
  CHECK_THROWS_WITH(sim.vjp_batch(x, u, Matrix<float>::Zero(6, 3), &out, nullptr),
                    Catch::Contains("lambda is 6 x 3; expected 6 x 4"));
  Matrix<float> lambda = Matrix<float>::Zero(6, 4);
  CHECK_THROWS_WITH(sim.vjp_batch(x, u, lambda, &lambda, nullptr),
                    Catch::Contains("lambda_x is lambda"));
}
