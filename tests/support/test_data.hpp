#pragma once
// Small builders of test inputs shared by the test files.
#include <cstdint>
#include <initializer_list>

#include "sbptt/core/rng.hpp"
#include "sbptt/core/types.hpp"

namespace sbptt::testing {

/// The vector of `values`, rounded to Scalar.
template <class Scalar>
Vector<Scalar> vec(std::initializer_list<double> values) {
  Vector<Scalar> v(static_cast<Index>(values.size()));
  Index i = 0;
  for (double x : values) v(i++) = static_cast<Scalar>(x);
  return v;
}

/// rows × cols entries uniform on [-scale, scale) from Rng(seed).
template <class Scalar>
Matrix<Scalar> random_matrix(Index rows, Index cols, std::uint64_t seed, double scale) {
  Rng rng(seed);
  Matrix<Scalar> x(rows, cols);
  for (Index i = 0; i < x.size(); ++i) x(i) = static_cast<Scalar>(rng.uniform(-scale, scale));
  return x;
}

/// Every parameter of `controller` uniform on [-scale, scale), biases included, so that every
/// gradient component is exercised.
template <class Ctrl>
void randomize(Ctrl& controller, std::uint64_t seed, double scale = 0.8) {
  controller.params() =
      random_matrix<typename Ctrl::Scalar>(controller.num_params(), 1, seed, scale);
}

}  // namespace sbptt::testing
