// One sign rule for the combined update and the diagnostics, whatever the include order.
// This file includes the optimizer first on purpose: with two `detail::tf_sign` (one mapping
// NaN to 0, one keeping NaN), the diagnostics' `compare` picked whichever was visible, and the
// agreement fraction of the same vectors depended on the order of the includes.
// clang-format off
#include "sbptt/optim/combined_update.hpp"
#include "sbptt/bptt/diagnostics.hpp"
// clang-format on

#include <catch2/catch.hpp>

#include <cmath>
#include <limits>

using sbptt::Vector;

TEMPLATE_TEST_CASE("compare() and the combined update count agreeing signs alike", "[core]",
                   float, double) {
  using Scalar = TestType;
  const Scalar nan = std::numeric_limits<Scalar>::quiet_NaN();
  // By the rule (NaN never agrees; two zeros agree): NaN/0 no, 1/1 yes, 0/0 yes, −2/3 no,
  // 0/−1 no, 5/NaN no → 2 of 6.
  Vector<Scalar> g_m(6), g_r(6);
  g_m << nan, 1, 0, -2, 0, 5;
  g_r << 0, 1, 0, 3, -1, nan;
  const double by_rule = 2.0 / 6.0;
  CHECK(sbptt::compare(g_m, g_r).agree_fraction == Approx(by_rule));
  CHECK(static_cast<double>(sbptt::sign_agreement(g_m, g_r)) == Approx(by_rule));
  // The combined update keeps exactly the agreeing components.
  Vector<Scalar> combined;
  sbptt::combine(g_m, g_r, combined);
  CHECK(combined(1) == Scalar(1));
  CHECK(combined(0) == Scalar(0));
  CHECK(combined(5) == Scalar(0));
}

TEST_CASE("one convention for empty vectors: nothing disagrees", "[core]") {
  const Vector<double> empty;
  CHECK(sbptt::sign_agreement(empty, empty) == 1.0);
  CHECK(sbptt::compare(empty, empty).agree_fraction == 1.0);
}
