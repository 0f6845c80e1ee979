// One sign rule for the combined update and the diagnostics, whatever the include order.
// This file includes the optimizer first on purpose: with two `detail::tf_sign` (one mapping
// NaN to 0, one keeping NaN), the diagnostics' `compare` picked whichever was visible, and the
// agreement fraction of the same vectors depended on the order of the includes.
// clang-format off
#include "sbptt/optim/combined_update.hpp"
#include "sbptt/bptt/diagnostics.hpp"
// clang-format on
#include "sbptt/core/rng.hpp"

#include <catch2/catch.hpp>

#include <cmath>
#include <cstring>
#include <limits>
#include <type_traits>
#include <vector>

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

TEMPLATE_TEST_CASE("the branch-free sign rule is tf.sign's equality with NaN excluded",
                   "[core]", float, double) {
  // Every pair of special and ordinary values, against the rule written out as in the file
  // comment of sign.hpp; then long vectors (whole registers and a tail) through the combined
  // update and the agreement fraction, against a loop over that definition.
  using Scalar = TestType;
  using limits = std::numeric_limits<Scalar>;
  const std::vector<Scalar> values = {
      Scalar(0), -Scalar(0), Scalar(1), Scalar(-3), limits::infinity(), -limits::infinity(),
      limits::quiet_NaN(), -limits::quiet_NaN(), limits::denorm_min(), -limits::denorm_min(),
      limits::max(), limits::lowest(), limits::min()};
  auto defined = [](Scalar m, Scalar r) {
    return !std::isnan(m) && !std::isnan(r) &&
           sbptt::detail::tf_sign(m) == sbptt::detail::tf_sign(r);
  };
  for (const Scalar m : values)
    for (const Scalar r : values) {
      INFO(m << " against " << r);
      CHECK(sbptt::detail::signs_agree(m, r) == defined(m, r));
    }
  const auto n = static_cast<sbptt::Index>(values.size() * values.size() * 3 + 5);
  Vector<Scalar> g_m(n), g_r(n), out;
  for (sbptt::Index i = 0; i < n; ++i) {
    const auto k = static_cast<std::size_t>(i) % (values.size() * values.size());
    g_m(i) = values[k / values.size()];
    g_r(i) = values[(k + static_cast<std::size_t>(i / 7)) % values.size()];
  }
  sbptt::Index agreeing = 0;
  for (sbptt::Index i = 0; i < n; ++i) agreeing += defined(g_m(i), g_r(i)) ? 1 : 0;
  CHECK(sbptt::detail::combine_counting(g_m, g_r, out) == agreeing);
  for (sbptt::Index i = 0; i < n; ++i) {
    INFO("component " << i);
    if (defined(g_m(i), g_r(i))) {
      CHECK(std::memcmp(&out(i), &g_m(i), sizeof(Scalar)) == 0);
    } else {
      CHECK(out(i) == Scalar(0));
    }
  }
  CHECK(sbptt::sign_agreement(g_m, g_r) ==
        sbptt::detail::agreement_fraction<Scalar>(agreeing, n));
}

TEMPLATE_TEST_CASE("compare() sums in one pass what loops in double sum", "[core]", float,
                   double) {
  // Whole registers, tails and vectors shorter than a register: cos(g_M, g_R) against the
  // sums in double, the agreement against the rule, and the agreement equal to the combined
  // update's count bit for bit.
  using Scalar = TestType;
  sbptt::Rng rng(7);
  for (const sbptt::Index n : {1, 7, 15, 16, 17, 40, 1000, 13004}) {
    Vector<Scalar> g_m(n), g_r(n), out;
    for (sbptt::Index i = 0; i < n; ++i) {
      g_m(i) = static_cast<Scalar>(rng.uniform() - 0.4);
      g_r(i) = i % 9 == 0 ? Scalar(0) : static_cast<Scalar>(rng.uniform() - 0.5);
      if (i % 11 == 0) g_m(i) = Scalar(0);
    }
    double dot = 0, mm = 0, rr = 0;
    sbptt::Index agreeing = 0;
    for (sbptt::Index i = 0; i < n; ++i) {
      dot += static_cast<double>(g_m(i)) * static_cast<double>(g_r(i));
      mm += static_cast<double>(g_m(i)) * static_cast<double>(g_m(i));
      rr += static_cast<double>(g_r(i)) * static_cast<double>(g_r(i));
      agreeing += sbptt::detail::signs_agree(g_m(i), g_r(i)) ? 1 : 0;
    }
    INFO("n = " << n);
    const auto c = sbptt::compare(g_m, g_r);
    const double cos = mm > 0 && rr > 0 ? dot / std::sqrt(mm * rr) : 0.0;
    CHECK(c.cos_modified_regular ==
          Approx(cos).margin(std::is_same_v<Scalar, float> ? 1e-5 : 1e-12));
    CHECK(c.agree_fraction == static_cast<double>(
                                  sbptt::detail::agreement_fraction<Scalar>(agreeing, n)));
    CHECK(sbptt::detail::combine_counting(g_m, g_r, out) == agreeing);
  }
}

TEMPLATE_TEST_CASE("compare() is exact for finite gradients whose squares leave the scalar's range",
                   "[core]", float, double) {
  // Exploding gradients are what the combined update is for: components near the largest
  // finite value made the sums of squares Inf and the cosine NaN (logged as "nan"); tiny ones
  // made them zero and the cosine 0 for equal vectors. The closed form: g_R = 2·g_M gives 1,
  // g_R = -g_M gives -1, orthogonal halves give 0.
  using Scalar = TestType;
  using Limits = std::numeric_limits<Scalar>;
  for (const Scalar scale : {Limits::max() / Scalar(4), Scalar(1e-3) * Limits::min(),
                             Limits::denorm_min() * Scalar(64)}) {
    for (const sbptt::Index n : {3, 16, 13004}) {
      INFO("scale = " << scale << ", n = " << n);
      Vector<Scalar> g_m(n), g_r(n), across(n);
      for (sbptt::Index i = 0; i < n; ++i) {
        g_m(i) = scale * (i % 3 == 0 ? Scalar(-0.5) : Scalar(0.25));
        across(i) = i < n / 2 ? g_m(i) : Scalar(0);
      }
      Vector<Scalar> rest = g_m - across;
      g_r = Scalar(2) * g_m;
      CHECK(sbptt::compare(g_m, g_r).cos_modified_regular == Approx(1.0).margin(1e-6));
      g_r = -g_m;
      CHECK(sbptt::compare(g_m, g_r).cos_modified_regular == Approx(-1.0).margin(1e-6));
      CHECK(sbptt::compare(across, rest).cos_modified_regular == Approx(0.0).margin(1e-6));
    }
  }
}

TEMPLATE_TEST_CASE("compare()'s cosine never leaves [-1, 1]", "[core]", float, double) {
  // dot / (‖a‖ ‖b‖) of parallel vectors rounds past ±1 (in float by up to 1.2e-7 in a fifth
  // of these trials), and a log then held a cosine above 1. The closed form: g and c·g give 1
  // for c > 0 and -1 for c < 0.
  using Scalar = TestType;
  sbptt::Rng rng(11);
  for (int trial = 0; trial < 300; ++trial) {
    for (const sbptt::Index n : {1, 2, 3, 7, 16, 17, 100, 13004}) {
      Vector<Scalar> g(n);
      for (sbptt::Index i = 0; i < n; ++i) g(i) = static_cast<Scalar>(rng.uniform() - 0.5);
      for (const Scalar c : {Scalar(1), Scalar(2), Scalar(-1), Scalar(-3)}) {
        const Vector<Scalar> scaled = c * g;
        const double cos = sbptt::compare(g, scaled).cos_modified_regular;
        INFO("trial " << trial << ", n = " << n << ", c = " << c << ", cos - sign(c) = "
                      << cos - (c > 0 ? 1.0 : -1.0));
        REQUIRE(std::abs(cos) <= 1.0);
        REQUIRE(cos == Approx(c > 0 ? 1.0 : -1.0).margin(1e-6));
      }
    }
  }
}

TEMPLATE_TEST_CASE("compare_and_combine gives compare's report and combine's vector in one pass",
                   "[core]", float, double) {
  // Whole registers, tails and vectors shorter than a register, with zeros of both signs and
  // NaNs: the report equal to `compare`'s and the vector to `combine`'s, bit for bit.
  using Scalar = TestType;
  const Scalar nan = std::numeric_limits<Scalar>::quiet_NaN();
  sbptt::Rng rng(11);
  for (const sbptt::Index n : {0, 1, 7, 16, 17, 40, 13004}) {
    Vector<Scalar> g_m(n), g_r(n), expected, combined;
    for (sbptt::Index i = 0; i < n; ++i) {
      g_m(i) = i % 13 == 5 ? -Scalar(0) : static_cast<Scalar>(rng.uniform() - 0.4);
      g_r(i) = i % 9 == 0 ? Scalar(0) : static_cast<Scalar>(rng.uniform() - 0.5);
      if (i % 17 == 3) g_r(i) = nan;
    }
    INFO("n = " << n);
    sbptt::combine(g_m, g_r, expected);
    const auto report = sbptt::compare_and_combine(g_m, g_r, combined);
    const auto alone = sbptt::compare(g_m, g_r);
    CHECK(report.cos_modified_regular == alone.cos_modified_regular);
    CHECK(report.agree_fraction == alone.agree_fraction);
    REQUIRE(combined.size() == n);
    // Not for n = 0: memcmp of null pointers is undefined, and GCC then drops the null test
    // of the vectors' destructors.
    if (n > 0)
      CHECK(std::memcmp(combined.data(), expected.data(),
                        sizeof(Scalar) * static_cast<std::size_t>(n)) == 0);
  }
  Vector<Scalar> g(3), shorter(2), out;
  g << 1, -2, 3;
  shorter << 1, 2;
  CHECK_THROWS_WITH(sbptt::compare_and_combine(g, shorter, out),
                    "compare_and_combine: g_R size = 2, expected the g_M size 3");
  CHECK_THROWS_WITH(sbptt::compare_and_combine(g, g, g),
                    "compare_and_combine: combined is g_M or g_R; expected a vector of its own");
}
