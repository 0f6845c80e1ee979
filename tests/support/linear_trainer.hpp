#pragma once
// A trainer of θ (c = θ₀ x² + θ₁ x, PolynomialPolicy with powers 2 and 1) on the linear system
// x' = 1.05 x + 0.5 c with the squared distance to the origin at every step, horizon 6: the
// small run of the training driver's tests.
#include "sbptt/bptt/losses.hpp"
#include "sbptt/optim/adam.hpp"
#include "sbptt/sim/linear.hpp"
#include "sbptt/train/trainer.hpp"
#include "polynomial_policy.hpp"

namespace sbptt::testing {

template <class Scalar>
using LinearSim = LinearSystem<Scalar, 1, 1>;
template <class Scalar>
using LinearLoss = SquaredDistanceLoss<typename LinearSim<Scalar>::State>;

template <class Scalar>
Objective<LinearLoss<Scalar>> to_origin() {
  return {LinearLoss<Scalar>{LinearSim<Scalar>::State::Zero()}, LossTiming::Continuous, 1.0,
          0.0};
}

/// `count` states first, first + 0.37, first + 0.74, …
template <class Scalar>
Matrix<Scalar> spread(Index count, double first) {
  Matrix<Scalar> m(1, count);
  for (Index i = 0; i < count; ++i) m(0, i) = static_cast<Scalar>(first + 0.37 * double(i));
  return m;
}

/// `Policy`: `PolynomialPolicy` or a controller built, like it, from its powers.
template <class Scalar, class Policy = PolynomialPolicy<Scalar>>
struct LinearTrainer {
  const LinearSim<Scalar> sim = LinearSim<Scalar>::scalar(Scalar(1.05), Scalar(0.5));
  Policy policy{{2, 1}};
  Trainer<LinearSim<Scalar>, Policy, LinearLoss<Scalar>, Adam<Scalar>> trainer;

  explicit LinearTrainer(Method method, Index batch = 3, double lr = 0.02,
                         NonFinitePolicy on_non_finite = NonFinitePolicy::Stop)
      : trainer(sim, policy, to_origin<Scalar>(), 6,
                Adam<Scalar>(AdamOptions<Scalar>{Scalar(lr)}),
                options(method, batch, on_non_finite)) {}

  static TrainerOptions options(Method method, Index batch, NonFinitePolicy on_non_finite) {
    TrainerOptions o;
    o.method = method;
    o.batch = batch;
    o.shuffle = true;
    o.shuffle_seed = 7;
    o.on_non_finite = on_non_finite;
    return o;
  }
};

}  // namespace sbptt::testing
