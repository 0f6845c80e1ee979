// GuidanceByRepulsion's batched step and vjp (float samples in SIMD lanes): against the
// per-sample step and vjp, against the analytic Jacobians in double (themselves checked against
// finite differences and automatic differentiation in test_sim_guidance.cpp and
// test_sim_autodiff_crosscheck.cpp), against central differences of the batched step itself,
// independence from the other columns, two agents on the same spot, and the pair call
// (vjp_batch_pair) against vjp_batch of the two batches side by side.
#include <catch2/catch.hpp>

#include <cmath>

#include "sbptt/core/concepts.hpp"
#include "sbptt/core/rng.hpp"
#include "sbptt/sim/guidance_task.hpp"
#include "support/batch_simulator.hpp"

namespace {

using sbptt::GuidanceByRepulsion;
using sbptt::GuidanceOptions;
using sbptt::Index;
using sbptt::Matrix;

struct Batch {
  Matrix<float> x, u, lambda;
};

// The paper's initial states with velocities added, controls in ±2, cotangents.
template <class Sim>
Batch random_batch(const Sim& sim, Index size, sbptt::Rng& rng) {
  Batch b{sbptt::guidance_initial_states(sim, rng, size), Matrix<float>(sim.control_dim(), size),
          Matrix<float>(sim.state_dim(), size)};
  for (Index c = 0; c < size; ++c) {
    for (Index a = 0; a < sim.agents(); ++a) {
      b.x(4 * a + 2, c) = static_cast<float>(rng.uniform(-1.0, 1.0));
      b.x(4 * a + 3, c) = static_cast<float>(rng.uniform(-1.0, 1.0));
    }
    for (Index i = 0; i < sim.control_dim(); ++i)
      b.u(i, c) = static_cast<float>(rng.uniform(-2.0, 2.0));
    for (Index i = 0; i < sim.state_dim(); ++i) b.lambda(i, c) = static_cast<float>(rng.normal());
  }
  return b;
}

GuidanceOptions intended() {
  GuidanceOptions options;
  options.physical.center = sbptt::GuidanceCenter::Centroid;
  options.physical.flocking = sbptt::FlockingSign::AsIntended;
  return options;
}

// Both are float: a few roundings of the square roots and divisions apart.
template <class Sim>
void check_against_per_sample(const Sim& sim, const Batch& b) {
  sbptt::testing::check_matches_per_sample(sim, b.x, b.u, b.lambda, 2e-6);
}

}  // namespace

TEST_CASE("guidance batch: step_batch and vjp_batch equal step and vjp per column",
          "[sim][guidance]") {
  sbptt::Rng rng(51);
  for (Index size : {1, 7, 8, 16, 19, 40}) {
    const GuidanceByRepulsion<float, 2, 4> paper;
    check_against_per_sample(paper, random_batch(paper, size, rng));
    const GuidanceByRepulsion<float, 3, 5> other(intended());
    check_against_per_sample(other, random_batch(other, size, rng));
  }
  const GuidanceByRepulsion<float, 1, 1> alone;  // no spreading, no flocking
  check_against_per_sample(alone, random_batch(alone, 9, rng));
}

TEST_CASE("guidance batch: vjp_batch equals the analytic Jacobians' products in double",
          "[sim][guidance]") {
  const GuidanceByRepulsion<float, 2, 4> sim;
  const GuidanceByRepulsion<double, 2, 4> reference;
  sbptt::Rng rng(52);
  const Batch b = random_batch(sim, 19, rng);
  Matrix<float> lambda_x, lambda_u;
  sim.vjp_batch(b.x, b.u, b.lambda, &lambda_x, &lambda_u);
  for (Index c = 0; c < b.x.cols(); ++c) {
    GuidanceByRepulsion<double, 2, 4>::StateJacobian a;
    GuidanceByRepulsion<double, 2, 4>::ControlJacobian control;
    const GuidanceByRepulsion<double, 2, 4>::State x = b.x.col(c).cast<double>();
    const GuidanceByRepulsion<double, 2, 4>::State lambda = b.lambda.col(c).cast<double>();
    const GuidanceByRepulsion<double, 2, 4>::Control u = b.u.col(c).cast<double>();
    reference.jacobians(x, u, a, control);
    const Eigen::VectorXd expected_x = a.transpose() * lambda;
    const Eigen::VectorXd expected_u = control.transpose() * lambda;
    INFO("column " << c);
    CHECK((lambda_x.col(c).cast<double>() - expected_x).norm() < 1e-5 * (1 + expected_x.norm()));
    CHECK((lambda_u.col(c).cast<double>() - expected_u).norm() < 1e-5 * (1 + expected_u.norm()));
  }
}

TEST_CASE("guidance batch: vjp_batch matches central differences of step_batch",
          "[sim][guidance]") {
  // ⟨λ, (P(x + εv, u + εw) − P(x − εv, u − εw)) / 2ε⟩ = ⟨Aᵀλ, v⟩ + ⟨Bᵀλ, w⟩ per column, in
  // float: ε = 1e-2 keeps the rounding of the difference near 1e-5.
  const GuidanceByRepulsion<float, 2, 4> sim;
  sbptt::Rng rng(53);
  const Index size = 21;
  const Batch b = random_batch(sim, size, rng);
  Matrix<float> v(sim.state_dim(), size), w(sim.control_dim(), size);
  for (Index i = 0; i < v.size(); ++i) v(i) = static_cast<float>(rng.uniform(-0.25, 0.25));
  for (Index i = 0; i < w.size(); ++i) w(i) = static_cast<float>(rng.uniform(-0.25, 0.25));
  Matrix<float> lambda_x, lambda_u, plus, minus;
  sim.vjp_batch(b.x, b.u, b.lambda, &lambda_x, &lambda_u);
  const float eps = 1e-2F;
  sim.step_batch(b.x + eps * v, b.u + eps * w, plus);
  sim.step_batch(b.x - eps * v, b.u - eps * w, minus);
  for (Index c = 0; c < size; ++c) {
    const double difference =
        b.lambda.col(c).cast<double>().dot((plus.col(c) - minus.col(c)).cast<double>()) /
        (2.0 * eps);
    const double adjoint = lambda_x.col(c).cast<double>().dot(v.col(c).cast<double>()) +
                           lambda_u.col(c).cast<double>().dot(w.col(c).cast<double>());
    INFO("column " << c);
    CHECK(std::abs(difference - adjoint) < 2e-3 * (1 + std::abs(adjoint)));
  }
}

TEST_CASE("guidance batch: a column's result does not depend on the other columns",
          "[sim][guidance]") {
  const GuidanceByRepulsion<float, 2, 4> sim;
  sbptt::Rng rng(54);
  const Batch b = random_batch(sim, 21, rng);
  sbptt::testing::check_columns_independent(sim, b.x, b.u, b.lambda);
}

TEST_CASE("guidance batch: two agents on one spot stay finite, in a lane beside others",
          "[sim][guidance]") {
  // n = 0 at coincidence (guidance_forces.hpp): the lane's select must not let 0/0 through.
  const GuidanceByRepulsion<float, 2, 4> sim;
  sbptt::Rng rng(55);
  Batch b = random_batch(sim, 5, rng);
  b.x.block<2, 1>(4, 2) = b.x.block<2, 1>(0, 2);    // both drivers of sample 2 on one spot
  b.x.block<2, 1>(12, 3) = b.x.block<2, 1>(8, 3);   // two evaders of sample 3
  b.x.block<2, 1>(8, 4) = b.x.block<2, 1>(0, 4);    // a driver on an evader, sample 4
  Matrix<float> next, lambda_x, lambda_u;
  sim.step_batch(b.x, b.u, next);
  sim.vjp_batch(b.x, b.u, b.lambda, &lambda_x, &lambda_u);
  CHECK(next.allFinite());
  CHECK(lambda_x.allFinite());
  CHECK(lambda_u.allFinite());
  check_against_per_sample(sim, b);
}

TEST_CASE("guidance batch: bad shapes are rejected with a message", "[sim][guidance]") {
  const GuidanceByRepulsion<float, 2, 4> sim;
  Matrix<float> out;
  const Matrix<float> x = Matrix<float>::Zero(24, 4), u = Matrix<float>::Zero(4, 4);
  CHECK_THROWS_WITH(sim.step_batch(Matrix<float>::Zero(23, 4), u, out),
                    Catch::Contains("x has 23 rows; expected state_dim() = 24"));
  CHECK_THROWS_WITH(sim.step_batch(x, Matrix<float>::Zero(4, 3), out),
                    Catch::Contains("u is 4 x 3; expected 4 x 4"));
  CHECK_THROWS_WITH(sim.vjp_batch(x, u, Matrix<float>::Zero(24, 3), &out, nullptr),
                    Catch::Contains("lambda is 24 x 3; expected 24 x 4"));
}

namespace {

// [a b]
Matrix<float> side_by_side(const Matrix<float>& a, const Matrix<float>& b) {
  Matrix<float> both(a.rows(), a.cols() + b.cols());
  both << a, b;
  return both;
}

}  // namespace

TEST_CASE("guidance batch: vjp_batch_pair gives vjp_batch of [x x], [u u], [λ₁ λ₂] bit for bit",
          "[sim][guidance]") {
  static_assert(sbptt::PairedBatchSimulator<GuidanceByRepulsion<float, 2, 4>>);
  const GuidanceByRepulsion<float, 2, 4> sim;
  sbptt::Rng rng(57);
  // 2B below, at and above a block of 16 lanes, and a block holding the end of λ₁ and the
  // start of λ₂ (B = 12, 17).
  for (Index size : {1, 5, 8, 12, 17}) {
    CAPTURE(size);
    const Batch b = random_batch(sim, size, rng);
    const Batch other = random_batch(sim, size, rng);
    Matrix<float> whole_x, whole_u;
    sim.vjp_batch(side_by_side(b.x, b.x), side_by_side(b.u, b.u),
                  side_by_side(b.lambda, other.lambda), &whole_x, &whole_u);
    Matrix<float> x_1, x_2, u_1, u_2;
    sim.vjp_batch_pair(b.x, b.u, b.lambda, other.lambda, &x_1, &x_2, &u_1, &u_2);
    CHECK(side_by_side(x_1, x_2) == whole_x);
    CHECK(side_by_side(u_1, u_2) == whole_u);
    Matrix<float> only_1, only_2;
    sim.vjp_batch_pair(b.x, b.u, b.lambda, other.lambda, nullptr, nullptr, &only_1, &only_2);
    CHECK(side_by_side(only_1, only_2) == whole_u);
  }
}

TEST_CASE("guidance batch: vjp_batch_pair rejects bad shapes and shared outputs",
          "[sim][guidance]") {
  const GuidanceByRepulsion<float, 2, 4> sim;
  const Matrix<float> u = Matrix<float>::Zero(4, 20);
  Matrix<float> x = Matrix<float>::Zero(24, 20), lambda = Matrix<float>::Zero(24, 20);
  Matrix<float> a, b, c, d;
  CHECK_THROWS_WITH(sim.vjp_batch_pair(x, u, lambda, Matrix<float>::Zero(24, 3), &a, &b, &c, &d),
                    Catch::Contains("vjp_batch_pair: lambda_2 is 24 x 3; expected 24 x 20"));
  CHECK_THROWS_WITH(sim.vjp_batch_pair(x, u, lambda, lambda, &a, nullptr, &c, &d),
                    Catch::Contains("lambda_x_1 is set and lambda_x_2 is null; expected both "
                                    "null or both set"));
  CHECK_THROWS_WITH(sim.vjp_batch_pair(x, u, lambda, lambda, &a, &b, &c, &c),
                    Catch::Contains("lambda_u_2 is lambda_u_1; expected a matrix of its own"));
  Matrix<float> adjoint = lambda;
  CHECK_THROWS_WITH(sim.vjp_batch_pair(x, u, lambda, adjoint, &adjoint, &b, &c, &d),
                    Catch::Contains("lambda_x_1 is lambda_2; expected a matrix of its own"));
  // 2B = 40 columns in three blocks: a block writing x's columns as outputs would change what
  // a later block reads for the other half.
  CHECK_THROWS_WITH(sim.vjp_batch_pair(x, u, lambda, adjoint, &x, &b, &c, &d),
                    Catch::Contains("lambda_x_1 is x; expected a matrix of its own"));
  // Nothing was resized before the checks threw.
  CHECK(a.size() == 0);
  CHECK(c.size() == 0);
}
