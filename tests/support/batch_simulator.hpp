#pragma once
// Checks shared by the tests of every BatchSimulator.
#include <catch2/catch.hpp>

#include "sbptt/core/finite_difference.hpp"
#include "sbptt/core/types.hpp"

namespace sbptt::testing {

/// Bit for bit, a column's step_batch and vjp_batch results do not depend on the other
/// columns: columns 0, 5, 15, 16 and 20 of the batch (x, u, lambda with 21 columns: in floats
/// the first, a middle and the last lane of a full 16-lane block, then of a partial one; in
/// doubles lanes of two full 8-lane blocks and of a partial one) against the same
/// sample alone among zero columns, at another place. This is what keeps training independent
/// of the batch's composition and the thread count, and what lets the engine hand both sweeps
/// of the combined update to one call. Also: x_next may be x itself.
template <class Sim, class Scalar>
void check_columns_independent(const Sim& sim, const Matrix<Scalar>& x, const Matrix<Scalar>& u,
                               const Matrix<Scalar>& lambda) {
  REQUIRE(x.cols() == 21);
  Matrix<Scalar> next, lambda_x, lambda_u;
  sim.step_batch(x, u, next);
  sim.vjp_batch(x, u, lambda, &lambda_x, &lambda_u);
  for (Index c : {0, 5, 15, 16, 20}) {
    const Index place = (c * 7 + 1) % 3;  // never c's own place: 1, 0, 1, 2, 0
    Matrix<Scalar> x_alone = Matrix<Scalar>::Zero(x.rows(), 3);
    Matrix<Scalar> u_alone = Matrix<Scalar>::Zero(u.rows(), 3);
    Matrix<Scalar> lambda_alone = Matrix<Scalar>::Zero(lambda.rows(), 3);
    x_alone.col(place) = x.col(c);
    u_alone.col(place) = u.col(c);
    lambda_alone.col(place) = lambda.col(c);
    Matrix<Scalar> alone_next, alone_x, alone_u;
    sim.step_batch(x_alone, u_alone, alone_next);
    sim.vjp_batch(x_alone, u_alone, lambda_alone, &alone_x, &alone_u);
    INFO("column " << c << " alone at " << place);
    CHECK(alone_next.col(place) == next.col(c));
    CHECK(alone_x.col(place) == lambda_x.col(c));
    CHECK(alone_u.col(place) == lambda_u.col(c));
  }
  Matrix<Scalar> in_place = x;
  sim.step_batch(in_place, u, in_place);
  CHECK(in_place == next);
}

/// The largest errors of step_batch's x_next and vjp_batch's Aᵀλ and Bᵀλ against step and vjp
/// column by column, each relative to 1 + the norm of the per-sample result; NaN if any column
/// holds a NaN (worst_error: std::max would drop one).
struct PerSampleErrors {
  double step = 0, state = 0, control = 0;
};

template <class Sim, class Scalar>
PerSampleErrors per_sample_errors(const Sim& sim, const Matrix<Scalar>& x,
                                  const Matrix<Scalar>& u, const Matrix<Scalar>& lambda) {
  Matrix<Scalar> next, lambda_x, lambda_u;
  sim.step_batch(x, u, next);
  sim.vjp_batch(x, u, lambda, &lambda_x, &lambda_u);
  REQUIRE(next.rows() == sim.state_dim());
  REQUIRE(next.cols() == x.cols());
  REQUIRE(lambda_u.rows() == sim.control_dim());
  REQUIRE(lambda_u.cols() == x.cols());
  PerSampleErrors errors;
  auto relative = [](const auto& got, const auto& expected) {
    return static_cast<double>((got - expected).norm() / (1 + expected.norm()));
  };
  for (Index c = 0; c < x.cols(); ++c) {
    typename Sim::State xc = x.col(c), lambda_c = lambda.col(c), expected, expected_x;
    typename Sim::Control uc = u.col(c), expected_u;
    sim.step(xc, uc, expected);
    sim.vjp(xc, uc, lambda_c, &expected_x, &expected_u);
    errors.step = worst_error({errors.step, relative(next.col(c), expected)});
    errors.state = worst_error({errors.state, relative(lambda_x.col(c), expected_x)});
    errors.control = worst_error({errors.control, relative(lambda_u.col(c), expected_u)});
  }
  return errors;
}

/// Each of `per_sample_errors` below `tolerance`.
template <class Sim, class Scalar>
void check_matches_per_sample(const Sim& sim, const Matrix<Scalar>& x, const Matrix<Scalar>& u,
                              const Matrix<Scalar>& lambda, double tolerance) {
  const PerSampleErrors errors = per_sample_errors(sim, x, u, lambda);
  INFO("batch " << x.cols());
  CHECK(errors.step < tolerance);
  CHECK(errors.state < tolerance);
  CHECK(errors.control < tolerance);
}

}  // namespace sbptt::testing
