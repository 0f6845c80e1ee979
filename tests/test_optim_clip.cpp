// Clipping by value and by global norm against closed forms, and the mode parser.
#include <catch2/catch.hpp>

#include <cmath>
#include <limits>
#include <string>

#include "support/test_data.hpp"
#include "sbptt/core/error.hpp"
#include "sbptt/optim/clip.hpp"

namespace {

using sbptt::testing::vec;

using sbptt::ClipMode;
using sbptt::Index;
using sbptt::Vector;

template <class Scalar>
double eps() {
  return static_cast<double>(8 * std::numeric_limits<Scalar>::epsilon());
}

}  // namespace

TEMPLATE_TEST_CASE("clip by value clamps each component and returns the pre-clip norm",
                   "[optim][clip]", float, double) {
  using Scalar = TestType;
  Vector<Scalar> g = vec<Scalar>({3.0, -0.5, -7.0, 0.0, 1.0});
  const Scalar norm = sbptt::clip(g, ClipMode::Value, Scalar(1));
  CHECK(static_cast<double>(norm) == Approx(std::sqrt(9.0 + 0.25 + 49.0 + 1.0)).epsilon(eps<Scalar>()));
  CHECK(g == vec<Scalar>({1.0, -0.5, -1.0, 0.0, 1.0}));

  Vector<Scalar> h = vec<Scalar>({0.2, -0.3});
  const Vector<Scalar> h0 = h;
  sbptt::clip(h, ClipMode::Value, Scalar(0.25));
  CHECK(h(0) == h0(0));
  CHECK(h(1) == Scalar(-0.25));

  Vector<Scalar> with_nan = vec<Scalar>({std::numeric_limits<double>::quiet_NaN(), 5.0});
  sbptt::clip(with_nan, ClipMode::Value, Scalar(1));
  CHECK(std::isnan(with_nan(0)));
  CHECK(with_nan(1) == Scalar(1));
}

TEMPLATE_TEST_CASE("clip by norm rescales to the threshold, leaves short vectors alone",
                   "[optim][clip]", float, double) {
  using Scalar = TestType;
  Vector<Scalar> g = vec<Scalar>({3.0, 4.0});
  CHECK(static_cast<double>(sbptt::clip(g, ClipMode::Norm, Scalar(1))) ==
        Approx(5.0).epsilon(eps<Scalar>()));
  CHECK(static_cast<double>(g(0)) == Approx(0.6).epsilon(eps<Scalar>()));
  CHECK(static_cast<double>(g(1)) == Approx(0.8).epsilon(eps<Scalar>()));
  CHECK(static_cast<double>(g.norm()) == Approx(1.0).epsilon(eps<Scalar>()));

  // g · t / max(‖g‖, t): below or at the threshold, unchanged bit for bit.
  for (double t : {10.0, 5.0}) {
    Vector<Scalar> h = vec<Scalar>({3.0, -4.0, 0.0});
    const Vector<Scalar> h0 = h;
    CHECK(static_cast<double>(sbptt::clip(h, ClipMode::Norm, static_cast<Scalar>(t))) ==
          Approx(5.0).epsilon(eps<Scalar>()));
    CHECK(h == h0);
  }

  // Squares that overflow Scalar still give a finite norm and a finite clipped vector.
  const Scalar big = std::sqrt(std::numeric_limits<Scalar>::max()) * Scalar(4);
  Vector<Scalar> huge(2);
  huge << big, -big;
  const Scalar huge_norm = sbptt::clip(huge, ClipMode::Norm, Scalar(1));
  CHECK(std::isfinite(huge_norm));
  CHECK(static_cast<double>(huge_norm / big) == Approx(std::sqrt(2.0)).epsilon(eps<Scalar>()));
  CHECK(static_cast<double>(huge(0)) == Approx(std::sqrt(0.5)).epsilon(eps<Scalar>()));
  CHECK(static_cast<double>(huge(1)) == Approx(-std::sqrt(0.5)).epsilon(eps<Scalar>()));

  // A non-finite norm makes every component NaN, as tf.clip_by_global_norm does.
  Vector<Scalar> inf = vec<Scalar>({1.0, std::numeric_limits<double>::infinity()});
  CHECK(std::isinf(sbptt::clip(inf, ClipMode::Norm, Scalar(1))));
  CHECK(inf.array().isNaN().all());
}

TEMPLATE_TEST_CASE("clip none leaves g alone but still reports the norm", "[optim][clip]", float,
                   double) {
  using Scalar = TestType;
  Vector<Scalar> g = vec<Scalar>({-2.0, 1.0, 2.0});
  const Vector<Scalar> g0 = g;
  CHECK(static_cast<double>(sbptt::clip(g, ClipMode::None, Scalar(1))) ==
        Approx(3.0).epsilon(eps<Scalar>()));
  CHECK(g == g0);
  // None never reads the threshold, so any value is accepted.
  CHECK_NOTHROW(sbptt::clip(g, ClipMode::None, Scalar(0)));
  Vector<Scalar> empty;
  CHECK(sbptt::clip(empty, ClipMode::Norm, Scalar(1)) == Scalar(0));
}

TEMPLATE_TEST_CASE("clip rejects thresholds that are not finite and positive", "[optim][clip]",
                   float, double) {
  using Scalar = TestType;
  Vector<Scalar> g = vec<Scalar>({1.0});
  for (ClipMode mode : {ClipMode::Value, ClipMode::Norm}) {
    for (Scalar t : {Scalar(0), Scalar(-1), std::numeric_limits<Scalar>::quiet_NaN(),
                     std::numeric_limits<Scalar>::infinity()}) {
      CHECK_THROWS_WITH(sbptt::clip(g, mode, t),
                        Catch::Contains("clip threshold") && Catch::Contains(sbptt::to_string(mode)));
    }
  }
  CHECK(g == vec<Scalar>({1.0}));
}

TEST_CASE("clip modes parse and print", "[optim][clip]") {
  for (ClipMode mode : {ClipMode::None, ClipMode::Value, ClipMode::Norm}) {
    CHECK(sbptt::parse_clip_mode(sbptt::to_string(mode)) == mode);
  }
  CHECK(sbptt::to_string(ClipMode::Norm) == "norm");
  CHECK(sbptt::parse_clip_mode("value") == ClipMode::Value);
  for (const char* bad : {"Norm", "clipnorm", "", "none "}) {
    CHECK_THROWS_WITH(sbptt::parse_clip_mode(bad),
                      Catch::Contains(std::string("\"") + bad + "\"") &&
                          Catch::Contains("none, value, norm"));
  }
}
