// sin and cos of doubles in registers (core/sine_cosine.hpp) against std::sin and std::cos,
// and the lane blocks of floats and doubles against the scalar form.
#include "sbptt/core/sine_cosine.hpp"

#include <catch2/catch.hpp>

#include <cmath>
#include <limits>
#include <numbers>
#include <random>
#include <vector>

namespace {

// The arguments: a dense sweep of [−50, 50]; random ones in [−1000, 1000] (a grid misses
// points that a sloppy cosine gets wrong); the doubles next to multiples of π/2 up to the
// reduction's limit (where r is smallest and a sloppy reduction shows most), with the
// quadrant boundaries ±π/4 + kπ/2; the limit 10^6 and past it; tiny, zero and non-finite.
std::vector<double> arguments() {
  std::vector<double> xs;
  for (int i = -100000; i <= 100000; ++i) xs.push_back(i * 5e-4);
  std::mt19937_64 generator(7);
  std::uniform_real_distribution<double> uniform(-1000.0, 1000.0);
  for (int i = 0; i < 400000; ++i) xs.push_back(uniform(generator));
  for (double k : {1.0, 2.0, 3.0, 4.0, 7.0, 100.0, 355.0, 1e3, 12345.0, 2e5, 636619.0}) {
    for (double sign : {1.0, -1.0}) {
      const double multiple = sign * k * std::numbers::pi / 2;
      const double boundary = multiple + sign * std::numbers::pi / 4;
      for (double x : {multiple, boundary})
        for (double y : {std::nextafter(x, 0.0), x, std::nextafter(x, 2 * x)}) xs.push_back(y);
    }
  }
  for (double x : {1e6, std::nextafter(1e6, 2e6), 1.5e6, 1e9, 1e300, 1e-300, 5e-324, 0.0,
                   std::numeric_limits<double>::infinity(),
                   std::numeric_limits<double>::quiet_NaN()}) {
    xs.push_back(x);
    xs.push_back(-x);
  }
  while (xs.size() % 8 != 0) xs.push_back(0.3);
  return xs;
}

// |got − expected| in units of the last place of expected (2^−1074 below the normal range).
double ulps(double got, double expected) {
  const double unit = std::max(std::abs(std::nextafter(expected, 2 * expected + 1) - expected),
                               std::numeric_limits<double>::denorm_min());
  return std::abs(got - expected) / unit;
}

template <class Packet>
void check_registers(const char* form) {
  INFO(form);
  const std::vector<double> xs = arguments();
  constexpr int lanes = Eigen::internal::unpacket_traits<Packet>::size;
  double worst_sine = 0, worst_cosine = 0;
  for (std::size_t i = 0; i < xs.size(); i += lanes) {
    Packet s, c;
    sbptt::detail::sine_cosine_packet_double(Eigen::internal::ploadu<Packet>(xs.data() + i), s,
                                             c);
    double sines[lanes], cosines[lanes];
    Eigen::internal::pstoreu(sines, s);
    Eigen::internal::pstoreu(cosines, c);
    for (int l = 0; l < lanes; ++l) {
      const double x = xs[i + static_cast<std::size_t>(l)];
      INFO("x = " << x);
      if (!std::isfinite(x)) {
        REQUIRE(std::isnan(sines[l]));
        REQUIRE(std::isnan(cosines[l]));
        continue;
      }
      REQUIRE(std::signbit(sines[l]) == std::signbit(std::sin(x)));
      worst_sine = std::max(worst_sine, ulps(sines[l], std::sin(x)));
      worst_cosine = std::max(worst_cosine, ulps(cosines[l], std::cos(x)));
    }
  }
  INFO("worst sine " << worst_sine << " ulp, worst cosine " << worst_cosine << " ulp");
  CHECK(worst_sine <= 2);
  CHECK(worst_cosine <= 2);
}

}  // namespace

TEST_CASE("sin and cos of doubles in registers are std::sin and std::cos to 2 ulp",
          "[core][sine_cosine]") {
  check_registers<typename Eigen::internal::packet_traits<double>::type>(
      "this build's widest register");
  check_registers<double>("a lone double (a build without SIMD)");
#if defined(EIGEN_VECTORIZE_SSE2)
  check_registers<Eigen::internal::Packet2d>("2 lanes");
#endif
}

TEST_CASE("a block of lanes gives each lane what its own value gives", "[core][sine_cosine]") {
  // A lane's result must not depend on the other lanes: a block with a lane past the
  // reduction's limit (taken by std::sin and std::cos) gives the other lanes the bits they
  // get in a block without it.
  using Block = Eigen::Array<double, 8, 1>;
  Block x, s, c, s_alone, c_alone;
  x << 0.1, -2.5, 3e6, 7.0, -1e-8, 40.0, -0.0, 1e5;
  sbptt::detail::sine_cosine(x, s, c);
  for (int l = 0; l < 8; ++l) {
    INFO("lane " << l);
    Block alone = Block::Constant(x(l));
    sbptt::detail::sine_cosine(alone, s_alone, c_alone);
    CHECK(s(l) == s_alone(0));
    CHECK(c(l) == c_alone(0));
  }
  CHECK(s(2) == std::sin(3e6));
  CHECK(c(2) == std::cos(3e6));

  // Floats go through Eigen's own, to float rounding of the double values.
  Eigen::Array<float, 16, 1> xf, sf, cf;
  for (int l = 0; l < 16; ++l) xf(l) = static_cast<float>(-7.0 + 0.9 * l);
  sbptt::detail::sine_cosine(xf, sf, cf);
  for (int l = 0; l < 16; ++l) {
    CHECK(sf(l) == Approx(std::sin(double(xf(l)))).margin(1e-6));
    CHECK(cf(l) == Approx(std::cos(double(xf(l)))).margin(1e-6));
  }
}
