// Schrodinger1D's batched step and vjp (samples in SIMD lanes): against the per-sample step and
// vjp (themselves checked against a dense solve and finite differences), against central
// differences of the batched step itself, unitarity, and independence from the other columns.
#include <catch2/catch.hpp>

#include <cmath>
#include <vector>

#include "sbptt/core/rng.hpp"
#include "sbptt/sim/schrodinger.hpp"
#include "support/batch_simulator.hpp"

namespace {

using sbptt::Index;
using sbptt::Matrix;

template <class Sim>
struct Batch {
  using Scalar = typename Sim::Scalar;
  Matrix<Scalar> x, u, lambda;
};

// Unit states, controls in ±20 (the paper's controls stay within a few units), cotangents.
template <class Sim>
Batch<Sim> random_batch(const Sim& sim, Index size, sbptt::Rng& rng) {
  using Scalar = typename Sim::Scalar;
  Batch<Sim> b{Matrix<Scalar>(sim.state_dim(), size), Matrix<Scalar>(1, size),
               Matrix<Scalar>(sim.state_dim(), size)};
  for (Index c = 0; c < size; ++c) {
    for (Index i = 0; i < sim.state_dim(); ++i) {
      b.x(i, c) = static_cast<Scalar>(rng.normal());
      b.lambda(i, c) = static_cast<Scalar>(rng.normal());
    }
    b.x.col(c) /= b.x.col(c).norm();
    b.u(0, c) = static_cast<Scalar>(rng.uniform(-20.0, 20.0));
  }
  return b;
}

// Largest difference between the batched and the per-sample results over all columns.
template <class Sim>
void check_against_per_sample(const Sim& sim, Index size, double tolerance, sbptt::Rng& rng) {
  using Scalar = typename Sim::Scalar;
  const Batch<Sim> b = random_batch(sim, size, rng);
  Matrix<Scalar> next, lambda_x, lambda_u;
  sim.step_batch(b.x, b.u, next);
  sim.vjp_batch(b.x, b.u, b.lambda, &lambda_x, &lambda_u);
  REQUIRE(next.cols() == size);
  REQUIRE(lambda_u.rows() == 1);
  double step_error = 0, state_error = 0, control_error = 0;
  for (Index c = 0; c < size; ++c) {
    typename Sim::State x = b.x.col(c), lambda = b.lambda.col(c), expected, expected_x;
    typename Sim::Control u = b.u.col(c), expected_u;
    sim.step(x, u, expected);
    sim.vjp(x, u, lambda, &expected_x, &expected_u);
    step_error = std::max(step_error, static_cast<double>((next.col(c) - expected).norm()));
    state_error = std::max(
        state_error, static_cast<double>((lambda_x.col(c) - expected_x).norm() / lambda.norm()));
    control_error =
        std::max(control_error, static_cast<double>(std::abs(lambda_u(0, c) - expected_u(0)) /
                                                    (lambda.norm() * (1 + std::abs(expected_u(0))))));
  }
  INFO("Nx = " << sim.grid_size() << ", batch " << size);
  CHECK(step_error < tolerance);
  CHECK(state_error < tolerance);
  CHECK(control_error < tolerance);
}

}  // namespace

TEST_CASE("schrodinger batch: step_batch and vjp_batch equal step and vjp per column",
          "[sim][quantum]") {
  sbptt::Rng rng(31);
  for (Index size : {1, 7, 8, 16, 19, 40}) {
    check_against_per_sample(sbptt::Schrodinger1D<double, 32>(), size, 1e-13, rng);
    check_against_per_sample(sbptt::Schrodinger1D<float, 32>(), size, 2e-5, rng);
  }
  check_against_per_sample(sbptt::Schrodinger1D<double, 1>(), 5, 1e-14, rng);
  check_against_per_sample(sbptt::Schrodinger1D<double, 9>({0.01, 50, 1.5}), 11, 1e-13, rng);
}

TEST_CASE("schrodinger batch: vjp_batch matches central differences of step_batch",
          "[sim][quantum]") {
  // ⟨λ, (P(x + εv, u + εw) − P(x − εv, u − εw)) / 2ε⟩ = ⟨Aᵀλ, v⟩ + (Bᵀλ)·w, per column.
  const sbptt::Schrodinger1D<double, 32> sim;
  sbptt::Rng rng(5);
  const Index size = 11;
  const auto b = random_batch(sim, size, rng);
  const auto direction = random_batch(sim, size, rng);
  Matrix<double> lambda_x, lambda_u, plus, minus;
  sim.vjp_batch(b.x, b.u, b.lambda, &lambda_x, &lambda_u);
  const double eps = 1e-6;
  const Matrix<double> w = direction.u / 20.0;
  sim.step_batch(b.x + eps * direction.x, b.u + eps * w, plus);
  sim.step_batch(b.x - eps * direction.x, b.u - eps * w, minus);
  for (Index c = 0; c < size; ++c) {
    const double difference = b.lambda.col(c).dot(plus.col(c) - minus.col(c)) / (2 * eps);
    const double adjoint = lambda_x.col(c).dot(direction.x.col(c)) + lambda_u(0, c) * w(0, c);
    CHECK(std::abs(difference - adjoint) < 1e-7 * (1 + std::abs(adjoint)));
  }
}

TEST_CASE("schrodinger batch: the step keeps each column's norm, and the state vjp too",
          "[sim][quantum]") {
  // M = U₁⁻¹U₂ is unitary, so ‖ψ'‖ = ‖ψ‖ and ‖Aᵀλ‖ = ‖λ‖ (A is orthogonal in the real layout).
  const sbptt::Schrodinger1D<double, 32> sim;
  sbptt::Rng rng(8);
  auto b = random_batch(sim, 19, rng);
  b.u *= 5.0;  // up to ±100
  Matrix<double> next, lambda_x;
  sim.step_batch(b.x, b.u, next);
  sim.vjp_batch(b.x, b.u, b.lambda, &lambda_x, nullptr);
  for (Index c = 0; c < b.x.cols(); ++c) {
    CHECK(std::abs(next.col(c).norm() - 1.0) < 1e-13);
    CHECK(std::abs(lambda_x.col(c).norm() / b.lambda.col(c).norm() - 1.0) < 1e-13);
  }
}

TEST_CASE("schrodinger batch: a column's result does not depend on the other columns",
          "[sim][quantum]") {
  const sbptt::Schrodinger1D<float, 32> sim;
  sbptt::Rng rng(12);
  const auto b = random_batch(sim, 21, rng);
  sbptt::testing::check_columns_independent(sim, b.x, b.u, b.lambda);
}

TEST_CASE("schrodinger batch: bad shapes are rejected with a message", "[sim][quantum]") {
  const sbptt::Schrodinger1D<double, 8> sim;
  Matrix<double> out;
  CHECK_THROWS_WITH(sim.step_batch(Matrix<double>::Zero(15, 3), Matrix<double>::Zero(1, 3), out),
                    Catch::Contains("states have 15 rows; expected 16"));
  CHECK_THROWS_WITH(sim.step_batch(Matrix<double>::Zero(16, 3), Matrix<double>::Zero(1, 2), out),
                    Catch::Contains("controls are 1 x 2; expected 1 x 3"));
  CHECK_THROWS_WITH(sim.vjp_batch(Matrix<double>::Zero(16, 3), Matrix<double>::Zero(1, 3),
                                  Matrix<double>::Zero(16, 2), &out, nullptr),
                    Catch::Contains("lambda is 16 x 2; expected 16 x 3"));
  static_assert(sbptt::BatchSimulator<sbptt::Schrodinger1D<float, 32>>);
  static_assert(!sbptt::BatchSimulator<sbptt::Schrodinger1D<double, Eigen::Dynamic>>);
}
