// The rotation picture of docs/paper.md §3.2 (and examples/rotation.cpp) as a check: on the bowl
// L = θ1² + θ2² from (2, 4), Adam converges on the gradient field, stalls on the rotated field,
// and the sign combination of the two recovers most of the progress.
#include <catch2/catch.hpp>

#include <algorithm>

#include "sbptt/optim/adam.hpp"
#include "sbptt/optim/combined_update.hpp"

namespace {

using sbptt::Vector;

// The same choices as the example: k = 2, lr = 0.1, 200 iterations, plain field v = θ.
constexpr double k_rotation = 2.0;
constexpr double k_lr = 0.1;
constexpr int k_iterations = 200;

template <class Scalar>
Vector<Scalar> plain_field(const Vector<Scalar>& theta) {
  return theta;
}

template <class Scalar>
Vector<Scalar> rotated_field(const Vector<Scalar>& theta) {
  const auto k = static_cast<Scalar>(k_rotation);
  Vector<Scalar> v(2);
  v << theta(0) - k * theta(1), theta(1) + k * theta(0);
  return v;
}

template <class Scalar>
Vector<Scalar> start() {
  Vector<Scalar> theta(2);
  theta << Scalar(2), Scalar(4);
  return theta;
}

template <class Scalar>
sbptt::Adam<Scalar> make_adam() {
  sbptt::AdamOptions<Scalar> options;
  options.learning_rate = static_cast<Scalar>(k_lr);
  return sbptt::Adam<Scalar>(options);
}

}  // namespace

TEMPLATE_TEST_CASE("rotation: plain < combined < rotated final loss", "[optim][rotation]", float,
                   double) {
  using Scalar = TestType;
  Vector<Scalar> plain = start<Scalar>(), rotated = start<Scalar>(), combined = start<Scalar>();
  auto plain_adam = make_adam<Scalar>();
  auto rotated_adam = make_adam<Scalar>();
  sbptt::CombinedUpdate<sbptt::Adam<Scalar>> combined_update(make_adam<Scalar>());
  int plain_below = -1;
  Scalar rotated_low = Scalar(1e30);
  for (int it = 1; it <= k_iterations; ++it) {
    plain_adam.step(plain, plain_field(plain));
    rotated_adam.step(rotated, rotated_field(rotated));
    combined_update.step(combined, rotated_field(combined), plain_field(combined));
    if (plain_below < 0 && plain.squaredNorm() < Scalar(1e-2)) plain_below = it;
    if (it > k_iterations / 2) rotated_low = std::min(rotated_low, rotated.squaredNorm());
  }
  const Scalar plain_loss = plain.squaredNorm();
  const Scalar rotated_loss = rotated.squaredNorm();
  const Scalar combined_loss = combined.squaredNorm();
  INFO("final losses: plain " << plain_loss << ", combined " << combined_loss << ", rotated "
                              << rotated_loss);
  CHECK(plain_loss < combined_loss);
  CHECK(combined_loss < rotated_loss);
  // The qualitative picture of the figure, not only the ordering.
  CHECK(plain_below > 0);
  CHECK(plain_below <= 60);
  CHECK(rotated_low > Scalar(0.5));         // the rotated run never settles over the 2nd half
  CHECK(combined_loss < Scalar(0.1) * rotated_low);
}
