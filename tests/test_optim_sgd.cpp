// SGD with and without heavy-ball momentum against values worked out by hand.
#include <catch2/catch.hpp>

#include <limits>
#include <vector>

#include "support/test_data.hpp"
#include "sbptt/core/error.hpp"
#include "sbptt/optim/sgd.hpp"

namespace {

using sbptt::testing::vec;

using sbptt::Index;
using sbptt::Vector;

template <class Scalar>
std::vector<Vector<Scalar>> gradients() {
  return {vec<Scalar>({1.0, 2.0}), vec<Scalar>({-1.0, 0.5}), vec<Scalar>({0.5, -0.5})};
}

template <class Scalar>
void check_close(const Vector<Scalar>& actual, std::initializer_list<double> expected) {
  REQUIRE(actual.size() == static_cast<Index>(expected.size()));
  Index i = 0;
  for (double e : expected) {
    CHECK(static_cast<double>(actual(i++)) ==
          Approx(e).epsilon(static_cast<double>(16 * std::numeric_limits<Scalar>::epsilon())));
  }
}

}  // namespace

TEMPLATE_TEST_CASE("Sgd without momentum: theta -= lr g", "[optim][sgd]", float, double) {
  using Scalar = TestType;
  sbptt::SgdOptions<Scalar> o;
  o.learning_rate = Scalar(0.1);
  sbptt::Sgd<Scalar> sgd(o);
  Vector<Scalar> theta = vec<Scalar>({1.0, -2.0});
  const auto g = gradients<Scalar>();
  sgd.step(theta, g[0]);
  check_close(theta, {0.9, -2.2});
  sgd.step(theta, g[1]);
  check_close(theta, {1.0, -2.25});
  sgd.step(theta, g[2]);
  check_close(theta, {0.95, -2.2});
  CHECK(sgd.iterations() == 3);
  CHECK(sgd.velocity().size() == 0);
}

TEMPLATE_TEST_CASE("Sgd with momentum: u = mu u + g, theta -= lr u", "[optim][sgd]", float,
                   double) {
  using Scalar = TestType;
  sbptt::SgdOptions<Scalar> o;
  o.learning_rate = Scalar(0.1);
  o.momentum = Scalar(0.9);
  sbptt::Sgd<Scalar> sgd(o);
  Vector<Scalar> theta = vec<Scalar>({1.0, -2.0});
  const auto g = gradients<Scalar>();
  // By hand: u1 = (1, 2)            θ1 = (0.9, −2.2)
  //          u2 = (−0.1, 2.3)       θ2 = (0.91, −2.43)
  //          u3 = (0.41, 1.57)      θ3 = (0.869, −2.587)
  sgd.step(theta, g[0]);
  check_close(theta, {0.9, -2.2});
  sgd.step(theta, g[1]);
  check_close(theta, {0.91, -2.43});
  check_close(sgd.velocity(), {-0.1, 2.3});
  sgd.step(theta, g[2]);
  check_close(theta, {0.869, -2.587});
  check_close(sgd.velocity(), {0.41, 1.57});

  // Keras's form (w ← μ w − lr g, θ ← θ + w) gives the same iterates at constant lr.
  Vector<Scalar> keras = vec<Scalar>({1.0, -2.0});
  Vector<Scalar> w = Vector<Scalar>::Zero(2);
  for (const auto& gi : g) {
    w = o.momentum * w - o.learning_rate * gi;
    keras += w;
  }
  check_close(theta, {static_cast<double>(keras(0)), static_cast<double>(keras(1))});

  sgd.reset();
  CHECK(sgd.iterations() == 0);
  CHECK(sgd.velocity().size() == 0);
  Vector<Scalar> three = vec<Scalar>({1.0, 1.0, 1.0});
  sgd.step(three, vec<Scalar>({1.0, 0.0, -1.0}));
  check_close(three, {0.9, 1.0, 1.1});
}

TEMPLATE_TEST_CASE("Sgd: bad options and sizes throw and name the value", "[optim][sgd]", float,
                   double) {
  using Scalar = TestType;
  sbptt::SgdOptions<Scalar> o;
  o.learning_rate = Scalar(-0.25);
  CHECK_THROWS_WITH(sbptt::Sgd<Scalar>(o), Catch::Contains("learning rate = -0.25"));
  o = {};
  o.momentum = Scalar(1);
  CHECK_THROWS_WITH(sbptt::Sgd<Scalar>(o), Catch::Contains("momentum = 1"));
  o = {};
  o.momentum = Scalar(0.5);
  sbptt::Sgd<Scalar> sgd(o);
  Vector<Scalar> theta = vec<Scalar>({1.0, 2.0});
  CHECK_THROWS_WITH(sgd.step(theta, vec<Scalar>({1.0})),
                    Catch::Contains("gradient size = 1") && Catch::Contains("parameter size 2"));
  sgd.step(theta, vec<Scalar>({1.0, 1.0}));
  Vector<Scalar> other = vec<Scalar>({1.0});
  CHECK_THROWS_AS(sgd.step(other, vec<Scalar>({1.0})), sbptt::InvalidArgument);
  CHECK_THROWS_AS(sgd.set_learning_rate(Scalar(0)), sbptt::InvalidArgument);
}
