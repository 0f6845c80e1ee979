// The sign rule in a program built with -ffinite-math-only (as -ffast-math implies; see
// tests/CMakeLists.txt): NaN still never agrees, whether it falls in a whole register of the
// pass or in its tail. GCC 12 took a NaN against 0 as agreeing there, so the combined update
// let NaNs of g_M through wherever g_R was 0.
#include <catch2/catch.hpp>

#include <cstring>
#include <limits>

#include "sbptt/core/sign.hpp"
#include "sbptt/optim/combined_update.hpp"

using sbptt::Index;
using sbptt::Vector;

TEMPLATE_TEST_CASE("under -ffinite-math-only NaN never agrees, in registers or in the tail",
                   "[core]", float, double) {
  using Scalar = TestType;
  const Scalar nan = std::numeric_limits<Scalar>::quiet_NaN();
  const Scalar tiny = std::numeric_limits<Scalar>::denorm_min();
  for (const Scalar other : {Scalar(0), -Scalar(0), Scalar(1), tiny}) {
    CHECK_FALSE(sbptt::detail::signs_agree(nan, other));
    CHECK_FALSE(sbptt::detail::signs_agree(other, nan));
    CHECK_FALSE(sbptt::detail::signs_agree(-nan, other));
  }
  CHECK(sbptt::detail::signs_agree(Scalar(0), -Scalar(0)));
  for (const Index n : {1, 7, 16, 33, 1000}) {
    INFO("n = " << n);
    Vector<Scalar> g_m = Vector<Scalar>::Constant(n, nan);
    Vector<Scalar> g_r = Vector<Scalar>::Zero(n);
    Vector<Scalar> out;
    CHECK(sbptt::detail::combine_counting(g_m, g_r, out) == 0);
    for (Index i = 0; i < n; ++i) {
      const Scalar zero(0);
      CHECK(std::memcmp(&out(i), &zero, sizeof(Scalar)) == 0);
    }
    CHECK(sbptt::sign_agreement(g_m, g_r) == Scalar(0));
  }
}
