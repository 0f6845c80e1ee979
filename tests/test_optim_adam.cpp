// Adam in the Keras / ResourceApplyAdam form against values computed independently: the
// formula as written in the paper (m ← β1 m + (1−β1) g, …) in long double, and literal values
// from 40-digit decimal arithmetic.
#include <catch2/catch.hpp>

#include <array>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "support/test_data.hpp"
#include "sbptt/core/error.hpp"
#include "sbptt/optim/adam.hpp"

namespace {

using sbptt::testing::vec;

using sbptt::Index;
using sbptt::Vector;

// The paper's formula, written independently of the library's evaluation order, in long
// double, from the Scalar-rounded inputs and hyper-parameters.
template <class Scalar>
std::vector<std::vector<long double>> reference_adam(const Vector<Scalar>& theta0,
                                                     const std::vector<Vector<Scalar>>& grads,
                                                     const sbptt::AdamOptions<Scalar>& o,
                                                     bool pytorch_epsilon = false) {
  using L = long double;
  const auto n = static_cast<std::size_t>(theta0.size());
  std::vector<L> th(n), m(n, 0), v(n, 0);
  for (std::size_t i = 0; i < n; ++i) th[i] = theta0(static_cast<Index>(i));
  const L lr = o.learning_rate, b1 = o.beta1, b2 = o.beta2, eps = o.epsilon;
  std::vector<std::vector<L>> out;
  for (std::size_t t = 1; t <= grads.size(); ++t) {
    const L c1 = 1 - std::pow(b1, static_cast<L>(t));
    const L c2 = 1 - std::pow(b2, static_cast<L>(t));
    for (std::size_t i = 0; i < n; ++i) {
      const L g = grads[t - 1](static_cast<Index>(i));
      m[i] = b1 * m[i] + (1 - b1) * g;
      v[i] = b2 * v[i] + (1 - b2) * g * g;
      if (pytorch_epsilon) {
        th[i] -= lr / c1 * m[i] / (std::sqrt(v[i] / c2) + eps);
      } else {
        th[i] -= lr * std::sqrt(c2) / c1 * m[i] / (std::sqrt(v[i]) + eps);
      }
    }
    out.push_back(th);
  }
  return out;
}

template <class Scalar>
Scalar tolerance() {
  return Scalar(64) * std::numeric_limits<Scalar>::epsilon();
}

}  // namespace

TEMPLATE_TEST_CASE("Adam: three steps match the formula computed in long double", "[optim][adam]",
                   float, double) {
  using Scalar = TestType;
  sbptt::AdamOptions<Scalar> options;
  options.learning_rate = Scalar(0.01);
  sbptt::Adam<Scalar> adam(options);

  // Mixed signs; the last component is exactly zero for two steps, then not.
  const Vector<Scalar> theta0 = vec<Scalar>({0.5, -1.5, 2.0});
  const std::vector<Vector<Scalar>> grads = {vec<Scalar>({0.2, -0.1, 0.0}),
                                             vec<Scalar>({-0.4, -0.3, 0.0}),
                                             vec<Scalar>({0.1, 0.6, 0.05})};
  const auto expected = reference_adam<Scalar>(theta0, grads, options);

  Vector<Scalar> theta = theta0;
  for (std::size_t t = 0; t < grads.size(); ++t) {
    adam.step(theta, grads[t]);
    CHECK(adam.iterations() == static_cast<Index>(t + 1));
    for (Index i = 0; i < 3; ++i) {
      const auto e = static_cast<double>(expected[t][static_cast<std::size_t>(i)]);
      CHECK(static_cast<double>(theta(i)) ==
            Approx(e).epsilon(static_cast<double>(tolerance<Scalar>())));
    }
  }
  // m = v = 0 while the gradient is exactly 0, so the component must not move at all.
  Vector<Scalar> probe = theta0;
  sbptt::Adam<Scalar> fresh(options);
  fresh.step(probe, grads[0]);
  fresh.step(probe, grads[1]);
  CHECK(probe(2) == theta0(2));
}

TEST_CASE("Adam: double steps match 40-digit decimal values", "[optim][adam]") {
  sbptt::AdamOptions<double> options;
  options.learning_rate = 0.01;
  sbptt::Adam<double> adam(options);
  Vector<double> theta = vec<double>({0.5, -1.5, 2.0});
  const std::vector<Vector<double>> grads = {vec<double>({0.2, -0.1, 0.0}),
                                             vec<double>({-0.4, -0.3, 0.0}),
                                             vec<double>({0.1, 0.6, 0.05})};
  // Python decimal, prec = 40, hyper-parameters as the exact doubles 0.9, 0.999, 1e-7, 0.01.
  const std::array<std::array<double, 3>, 3> expected = {{
      {0.4900001581113830479467262159507813006336, -1.490000316217766333055527246431990795698,
       2.0},
      {0.4936611674919068009909461381183719390886, -1.480822596809746572182048124282925121236,
       2.0},
      {0.4950280646845345722361040647188459964663, -1.483168145686069835034270101160867578601,
       1.993612268001658793483178355735134926023},
  }};
  for (std::size_t t = 0; t < 3; ++t) {
    adam.step(theta, grads[t]);
    for (Index i = 0; i < 3; ++i) {
      CHECK(theta(i) == Approx(expected[t][static_cast<std::size_t>(i)]).epsilon(1e-14));
    }
  }
}

TEMPLATE_TEST_CASE("Adam: epsilon is added to the uncorrected sqrt(v), unlike PyTorch",
                   "[optim][adam]", float, double) {
  using Scalar = TestType;
  sbptt::AdamOptions<Scalar> options;
  options.learning_rate = Scalar(0.1);
  const Scalar g = Scalar(1e-9);  // √v ≪ ε: the regime where the placement matters

  sbptt::Adam<Scalar> adam(options);
  Vector<Scalar> theta = Vector<Scalar>::Zero(1);
  adam.step(theta, vec<Scalar>({static_cast<double>(g)}));
  const long double step = -static_cast<long double>(theta(0));

  // At t = 1 the Keras step is lr·g/(|g| + ε/√(1−β2)); PyTorch's is lr·g/(|g| + ε).
  const long double lr = options.learning_rate, eps = options.epsilon, gl = g;
  const long double c2 = 1 - static_cast<long double>(options.beta2);
  const long double keras = lr * gl / (gl + eps / std::sqrt(c2));
  const long double pytorch = lr * gl / (gl + eps);
  CHECK(static_cast<double>(step) ==
        Approx(static_cast<double>(keras)).epsilon(static_cast<double>(tolerance<Scalar>())));
  // The expected gap: (|g| + ε)/(|g| + ε/√(1−β2)) ≈ √(1−β2) = 0.0316 when |g| ≪ ε.
  const double ratio = static_cast<double>(step / pytorch);
  CHECK(ratio == Approx(static_cast<double>((gl + eps) / (gl + eps / std::sqrt(c2)))).epsilon(1e-5));
  CHECK(ratio < 0.04);

  // Over several steps the PyTorch-ε reference differs, the Keras-ε one agrees.
  sbptt::Adam<Scalar> adam3(options);
  Vector<Scalar> theta3 = Vector<Scalar>::Zero(1);
  const std::vector<Vector<Scalar>> grads(3, vec<Scalar>({static_cast<double>(g)}));
  for (const auto& gr : grads) adam3.step(theta3, gr);
  const auto keras3 = reference_adam<Scalar>(Vector<Scalar>::Zero(1), grads, options, false);
  const auto torch3 = reference_adam<Scalar>(Vector<Scalar>::Zero(1), grads, options, true);
  CHECK(static_cast<double>(theta3(0)) ==
        Approx(static_cast<double>(keras3[2][0])).epsilon(static_cast<double>(tolerance<Scalar>())));
  CHECK(std::abs(static_cast<double>(theta3(0) - static_cast<Scalar>(torch3[2][0]))) >
        0.5 * std::abs(static_cast<double>(torch3[2][0])));

  // With √v ≫ ε the two forms agree to O(ε/|g|).
  sbptt::Adam<Scalar> big(options);
  Vector<Scalar> theta_big = Vector<Scalar>::Zero(1);
  big.step(theta_big, vec<Scalar>({1.0}));
  CHECK(static_cast<double>(-theta_big(0)) == Approx(static_cast<double>(lr)).epsilon(1e-5));
}

TEMPLATE_TEST_CASE("Adam: state, reset and restore", "[optim][adam]", float, double) {
  using Scalar = TestType;
  sbptt::Adam<Scalar> adam;
  CHECK(adam.iterations() == 0);
  CHECK(adam.first_moment().size() == 0);
  CHECK(adam.options().learning_rate == Scalar(1e-3));
  CHECK(adam.options().beta1 == Scalar(0.9));
  CHECK(adam.options().beta2 == Scalar(0.999));
  CHECK(adam.options().epsilon == Scalar(1e-7));

  Vector<Scalar> theta = vec<Scalar>({1.0, -1.0});
  const std::vector<Vector<Scalar>> grads = {vec<Scalar>({0.3, -2.0}), vec<Scalar>({-0.1, 0.0}),
                                             vec<Scalar>({0.7, 0.2}), vec<Scalar>({0.0, -0.4})};
  adam.step(theta, grads[0]);
  adam.step(theta, grads[1]);
  CHECK(adam.first_moment().size() == 2);

  // A checkpointed copy continues bit for bit like the uninterrupted run.
  sbptt::Adam<Scalar> resumed;
  resumed.restore(adam.first_moment(), adam.second_moment(), adam.iterations());
  Vector<Scalar> theta_resumed = theta;
  for (std::size_t t = 2; t < grads.size(); ++t) {
    adam.step(theta, grads[t]);
    resumed.step(theta_resumed, grads[t]);
  }
  CHECK(theta_resumed == theta);
  CHECK(resumed.iterations() == 4);

  // After reset the first step is again a first step, of any size.
  adam.reset();
  CHECK(adam.iterations() == 0);
  Vector<Scalar> a = vec<Scalar>({1.0, 2.0, 3.0});
  Vector<Scalar> b = a;
  adam.step(a, vec<Scalar>({0.1, 0.2, 0.3}));
  sbptt::Adam<Scalar> fresh;
  fresh.step(b, vec<Scalar>({0.1, 0.2, 0.3}));
  CHECK(a == b);

  CHECK_THROWS_AS(resumed.restore(vec<Scalar>({1.0}), vec<Scalar>({1.0, 2.0}), 3),
                  sbptt::InvalidArgument);
  CHECK_THROWS_AS(resumed.restore(vec<Scalar>({1.0}), vec<Scalar>({-1.0}), 3),
                  sbptt::InvalidArgument);
  CHECK_THROWS_AS(resumed.restore(vec<Scalar>({1.0}), vec<Scalar>({1.0}), 0),
                  sbptt::InvalidArgument);
}

TEMPLATE_TEST_CASE("Adam: bad options and sizes throw and name the value", "[optim][adam]", float,
                   double) {
  using Scalar = TestType;
  const Scalar nan = std::numeric_limits<Scalar>::quiet_NaN();
  const Scalar inf = std::numeric_limits<Scalar>::infinity();
  for (Scalar lr : {Scalar(0), Scalar(-1), nan, inf}) {
    sbptt::AdamOptions<Scalar> o;
    o.learning_rate = lr;
    CHECK_THROWS_WITH(sbptt::Adam<Scalar>(o), Catch::Contains("learning rate"));
  }
  sbptt::AdamOptions<Scalar> o;
  o.beta1 = Scalar(1);
  CHECK_THROWS_WITH(sbptt::Adam<Scalar>(o), Catch::Contains("beta1 = 1"));
  o = {};
  o.beta2 = Scalar(-0.5);
  CHECK_THROWS_WITH(sbptt::Adam<Scalar>(o), Catch::Contains("beta2 = -0.5"));
  o = {};
  o.epsilon = Scalar(0);
  CHECK_THROWS_WITH(sbptt::Adam<Scalar>(o), Catch::Contains("epsilon = 0"));

  sbptt::Adam<Scalar> adam;
  CHECK_THROWS_WITH(adam.set_learning_rate(nan), Catch::Contains("learning rate = nan"));
  Vector<Scalar> theta = vec<Scalar>({1.0, 2.0, 3.0});
  CHECK_THROWS_WITH(adam.step(theta, vec<Scalar>({1.0, 2.0})),
                    Catch::Contains("gradient size = 2") && Catch::Contains("parameter size 3"));
  CHECK(adam.iterations() == 0);  // a rejected step changes nothing
  adam.step(theta, vec<Scalar>({1.0, 2.0, 3.0}));
  Vector<Scalar> other = vec<Scalar>({1.0, 2.0});
  CHECK_THROWS_WITH(adam.step(other, vec<Scalar>({1.0, 2.0})),
                    Catch::Contains("parameter size = 2") && Catch::Contains("reset()"));
}

TEMPLATE_TEST_CASE("Adam: a fixed gradient sequence gives bitwise-identical parameters",
                   "[optim][adam]", float, double) {
  using Scalar = TestType;
  auto run = [] {
    sbptt::AdamOptions<Scalar> o;
    o.learning_rate = Scalar(0.05);
    sbptt::Adam<Scalar> adam(o);
    Vector<Scalar> theta = Vector<Scalar>::LinSpaced(37, Scalar(-1), Scalar(1));
    for (int t = 0; t < 50; ++t) {
      Vector<Scalar> g(theta.size());
      for (Index i = 0; i < g.size(); ++i) {
        g(i) = static_cast<Scalar>(std::sin(0.7 * static_cast<double>(t) + static_cast<double>(i)));
        if ((i + t) % 5 == 0) g(i) = Scalar(0);
      }
      adam.step(theta, g);
    }
    return theta;
  };
  const Vector<Scalar> first = run();
  const Vector<Scalar> second = run();
  CHECK(first == second);
}
