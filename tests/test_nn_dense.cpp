// Dense layers and MLPs: closed-form forward values, parameter counts from the paper,
// finite-difference checks of both vector–Jacobian products, and input validation.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <thread>
#include <utility>
#include <vector>

#include "support/test_data.hpp"
#include "sbptt/core/controller_check.hpp"
#include "sbptt/nn/init.hpp"
#include "sbptt/nn/network.hpp"

using sbptt::Activation;
using sbptt::Dense;
using sbptt::Index;
using sbptt::Network;

namespace {

using sbptt::testing::randomize;
template <class Scalar>
sbptt::Matrix<Scalar> random_batch(Index rows, Index cols, std::uint64_t seed) {
  return sbptt::testing::random_matrix<Scalar>(rows, cols, seed, 1.5);
}

}  // namespace

TEMPLATE_TEST_CASE("dense forward matches a hand computation", "[nn][dense]", float, double) {
  using S = TestType;
  // 2 → 2 (tanh) → 1 (identity); the flat vector spells out W1 row by row, b1, W2, b2.
  Network<S> net({Dense{2, 2, Activation::Tanh}, Dense{2, 1, Activation::Identity}});
  REQUIRE(net.num_params() == 9);
  net.params() << S(0.1), S(-0.2), S(0.3), S(0.4), S(0.05), S(-0.1), S(0.5), S(-1.5), S(0.2);
  sbptt::Matrix<S> x(2, 2);
  x << S(1), S(-1),
       S(2), S(0.5);
  sbptt::Matrix<S> y;
  typename Network<S>::Workspace ws;
  net.forward(x, y, ws);
  REQUIRE(y.rows() == 1);
  REQUIRE(y.cols() == 2);
  // Sample 0: z1 = 0.1·1 − 0.2·2 + 0.05 = −0.25, z2 = 0.3·1 + 0.4·2 − 0.1 = 1.0.
  const double y0 = 0.5 * std::tanh(-0.25) - 1.5 * std::tanh(1.0) + 0.2;
  // Sample 1: z1 = −0.1 − 0.1 + 0.05 = −0.15, z2 = −0.3 + 0.2 − 0.1 = −0.2.
  const double y1 = 0.5 * std::tanh(-0.15) - 1.5 * std::tanh(-0.2) + 0.2;
  const double tol = std::is_same_v<S, float> ? 1e-6 : 1e-15;
  CHECK(static_cast<double>(y(0, 0)) == Approx(y0).margin(tol));
  CHECK(static_cast<double>(y(0, 1)) == Approx(y1).margin(tol));
  CHECK(ws.batch_size() == 2);
}

TEMPLATE_TEST_CASE("MLP sizes and parameter counts match the paper", "[nn][dense]", float,
                   double) {
  using S = TestType;
  const auto gbr = Network<S>::mlp(24, {100, 100}, 4);  // guidance by repulsion, 2 drivers
  CHECK(gbr.num_params() == 13004);
  CHECK(gbr.input_dim() == 24);
  CHECK(gbr.output_dim() == 4);
  CHECK(gbr.num_layers() == 3);
  CHECK(sbptt::layer_activation(gbr.layers()[0]) == Activation::Tanh);
  CHECK(sbptt::layer_activation(gbr.layers()[2]) == Activation::Identity);
  CHECK(gbr.param_offset(1) == 24 * 100 + 100);
  CHECK(Network<S>::mlp(10, {100, 100}, 1).num_params() == 11301);  // cart pole, 4 poles
  CHECK(Network<S>::mlp(4, {100, 100}, 1).num_params() == 10701);   // cart pole, 1 pole
  CHECK(gbr.params().size() == 13004);
  CHECK(gbr.params().isZero(0));

  sbptt::Matrix<S> y;
  typename Network<S>::Workspace ws;
  gbr.forward(random_batch<S>(24, 7, 3), y, ws);
  CHECK(y.rows() == 4);
  CHECK(y.cols() == 7);
}

TEST_CASE("dense backward equals central finite differences", "[nn][dense]") {
  struct Case {
    std::vector<Index> sizes;
    Activation hidden;
    Activation last;
  };
  const std::vector<Case> cases = {
      {{3, 2}, Activation::Identity, Activation::Identity},
      {{3, 2}, Activation::Tanh, Activation::Tanh},
      {{1, 1}, Activation::Tanh, Activation::Tanh},
      {{5, 7, 4}, Activation::Tanh, Activation::Identity},
      {{4, 6, 6, 3}, Activation::Tanh, Activation::Tanh},
      {{6, 5, 2}, Activation::Identity, Activation::Tanh},
  };
  std::uint64_t seed = 10;
  for (const auto& c : cases) {
    std::vector<sbptt::Layer> layers;
    for (std::size_t i = 0; i + 1 < c.sizes.size(); ++i)
      layers.emplace_back(Dense{c.sizes[i], c.sizes[i + 1],
                                i + 2 == c.sizes.size() ? c.last : c.hidden});
    Network<double> net(layers);
    randomize(net, ++seed);
    for (const Index batch : {1, 5}) {
      INFO(net.describe() << ", batch " << batch);
      const auto x = random_batch<double>(net.input_dim(), batch, ++seed);
      const auto check = sbptt::check_controller(net, x, seed);
      CHECK(check.worst() <= 1e-6);  // every path the engine may take
      CHECK(check.has_column_split == (batch > 1));  // a batch of 1 has no cut
      CHECK(check.column_split_forward_error == 0);
    }
  }
}

TEST_CASE("the paper's MLP backward equals central finite differences", "[nn][dense]") {
  auto net = Network<double>::mlp(10, {100, 100}, 1);
  sbptt::Rng rng(42);
  sbptt::glorot_uniform(net, rng);  // last kernel random, so the input VJP is not trivially 0
  const auto check = sbptt::check_controller(net, random_batch<double>(10, 5, 8), 9);
  CHECK(check.worst() <= 1e-6);  // every path the engine may take
  CHECK(check.has_column_split);
  CHECK(check.column_split_forward_error == 0);
}

TEST_CASE("backward accumulates into grad and skips the input VJP on request", "[nn][dense]") {
  auto net = Network<double>::mlp(6, {8, 5}, 3);
  randomize(net, 77);
  const auto x = random_batch<double>(6, 5, 78);
  const auto dy = random_batch<double>(3, 5, 79);
  sbptt::Matrix<double> y, dx;
  Network<double>::Workspace ws;
  net.forward(x, y, ws);

  Eigen::VectorXd with_dx = Eigen::VectorXd::Zero(net.num_params());
  net.backward(ws, dy, with_dx, &dx);
  Eigen::VectorXd without_dx = Eigen::VectorXd::Zero(net.num_params());
  net.backward(ws, dy, without_dx, nullptr);
  CHECK(with_dx == without_dx);  // bitwise: the same operations in the same order
  CHECK(dx.rows() == 6);
  CHECK(dx.cols() == 5);
  CHECK(with_dx.norm() > 0);

  // "Adds": a second call onto a non-zero grad gives the sum.
  Eigen::VectorXd twice = with_dx;
  net.backward(ws, dy, twice, nullptr);
  CHECK(twice.isApprox(2 * with_dx, 1e-14));

  // The batch gradient is the sum of the per-sample gradients.
  Eigen::VectorXd summed = Eigen::VectorXd::Zero(net.num_params());
  for (Index b = 0; b < 5; ++b) {
    Network<double>::Workspace one;
    net.forward(x.col(b), y, one);
    net.backward(one, dy.col(b), summed, nullptr);
  }
  CHECK(summed.isApprox(with_dx, 1e-13));
}

TEST_CASE("backward may run on one workspace from several threads at once", "[nn][dense]") {
  // The combined update sweeps twice from one forward pass; the sweeps may run in parallel.
  auto net = Network<double>::mlp(6, {40, 40}, 3);
  randomize(net, 5);
  const auto x = random_batch<double>(6, 8, 6);
  sbptt::Matrix<double> y;
  Network<double>::Workspace ws;
  net.forward(x, y, ws);
  const auto dy_a = random_batch<double>(3, 8, 7);
  const auto dy_b = random_batch<double>(3, 8, 8);
  auto run = [&](const sbptt::Matrix<double>& dy, Eigen::VectorXd& grad,
                 sbptt::Matrix<double>& dx) {
    grad = Eigen::VectorXd::Zero(net.num_params());
    for (int repeat = 0; repeat < 50; ++repeat) net.backward(ws, dy, grad, &dx);
  };
  Eigen::VectorXd serial_a, serial_b, parallel_a, parallel_b;
  sbptt::Matrix<double> dx_sa, dx_sb, dx_pa, dx_pb;
  run(dy_a, serial_a, dx_sa);
  run(dy_b, serial_b, dx_sb);
  std::thread ta([&] { run(dy_a, parallel_a, dx_pa); });
  std::thread tb([&] { run(dy_b, parallel_b, dx_pb); });
  ta.join();
  tb.join();
  CHECK(parallel_a == serial_a);
  CHECK(parallel_b == serial_b);
  CHECK(dx_pa == dx_sa);
  CHECK(dx_pb == dx_sb);
}

TEST_CASE("dense networks reject malformed layers and inputs", "[nn][dense]") {
  using Catch::Contains;
  REQUIRE_THROWS_WITH(Network<double>({Dense{4, 3, Activation::Tanh}, Dense{5, 1}}),
                      Contains("expects 5 inputs") && Contains("produces 3"));
  REQUIRE_THROWS_AS(Network<double>(std::vector<sbptt::Layer>{}), sbptt::InvalidArgument);
  REQUIRE_THROWS_WITH(Network<double>({Dense{0, 3}}), Contains("inputs = 0"));
  REQUIRE_THROWS_WITH(Network<double>::mlp(4, {100, -2}, 1), Contains("outputs = -2"));

  auto net = Network<double>::mlp(4, {3}, 2);
  sbptt::Matrix<double> y, dx;
  Network<double>::Workspace ws;
  REQUIRE_THROWS_WITH(net.forward(sbptt::Matrix<double>::Zero(5, 2), y, ws),
                      Contains("X has 5 rows") && Contains("input_dim() = 4"));
  Eigen::VectorXd grad = Eigen::VectorXd::Zero(net.num_params());
  REQUIRE_THROWS_WITH(net.backward(ws, sbptt::Matrix<double>::Zero(2, 2), grad, nullptr),
                      Contains("no forward pass"));
  net.forward(sbptt::Matrix<double>::Zero(4, 2), y, ws);
  REQUIRE_THROWS_WITH(net.backward(ws, sbptt::Matrix<double>::Zero(2, 3), grad, nullptr),
                      Contains("dY is 2 × 3") && Contains("expected 2 × 2"));
  Eigen::VectorXd short_grad = Eigen::VectorXd::Zero(3);
  REQUIRE_THROWS_WITH(net.backward(ws, sbptt::Matrix<double>::Zero(2, 2), short_grad, nullptr),
                      Contains("grad has 3 entries"));
  const auto other = Network<double>::mlp(4, {7}, 2);
  Eigen::VectorXd other_grad = Eigen::VectorXd::Zero(other.num_params());
  REQUIRE_THROWS_WITH(other.backward(ws, sbptt::Matrix<double>::Zero(2, 2), other_grad, nullptr),
                      Contains("different network"));
  net.params().resize(5);
  REQUIRE_THROWS_WITH(net.forward(sbptt::Matrix<double>::Zero(4, 2), y, ws),
                      Contains("params() has 5 entries"));
}

TEST_CASE("the double tanh's 2^k equals std::ldexp(1, k)", "[nn][activation]") {
  // Every k for which 2^k is a normal double, in every lane (k, k + 1, … across a register),
  // through each form the tanh can use.
  auto check = [](auto packet, const char* form, auto power_of_two) {
    using Packet = decltype(packet);
    constexpr int lanes = Eigen::internal::unpacket_traits<Packet>::size;
    INFO(form);
    for (int first = -1022; first + lanes - 1 <= 1023; ++first) {
      double biased[lanes], k[lanes], got[lanes];
      for (int l = 0; l < lanes; ++l) {
        k[l] = first + l;
        biased[l] = k[l] + 1023 + 6755399441055744.0;
      }
      Eigen::internal::pstoreu(got, power_of_two(Eigen::internal::ploadu<Packet>(biased),
                                                 Eigen::internal::ploadu<Packet>(k)));
      for (int l = 0; l < lanes; ++l) REQUIRE(got[l] == std::ldexp(1.0, first + l));
    }
  };
  auto chosen = [](const auto& biased, const auto& k) {
    return sbptt::detail::power_of_two(biased, k);
  };
  auto portable = [](const auto& biased, const auto& k) {
    return sbptt::detail::power_of_two_portable(biased, k);
  };
  using Widest = typename Eigen::internal::packet_traits<double>::type;
  check(Widest{}, "this build's widest register", chosen);
  check(Widest{}, "the portable form, widest register", portable);
  check(double{}, "a lone double", chosen);
#if defined(EIGEN_VECTORIZE_SSE2)
  check(Eigen::internal::Packet2d{}, "2 lanes", chosen);
#endif
}

TEST_CASE("the vectorised double tanh equals std::tanh to round-off", "[nn][activation]") {
  // Dense sweep of [−20, 20], where k = round(2|x| / ln 2) takes every value it can; the
  // arguments where k steps from 0 to 1 (2|x| = ln2/2, where 2^k − 1 and 2^k (e^r − 1) cancel
  // most), where the clamp 2|x| ≤ 40 starts, tiny and huge arguments, and the non-finite ones.
  // In this build's widest register, (on x86) in SSE2's 2 lanes, and as a lone double (a build
  // without SIMD).
  std::vector<double> xs;
  for (int i = -40000; i <= 40000; ++i) xs.push_back(i * 5e-4);
  const double k_steps = std::log(2.0) / 4;
  for (double x : {k_steps, std::nextafter(k_steps, 0.0), std::nextafter(k_steps, 1.0), 1e-300,
                   5e-324, 0.0, -0.0, 19.0, 20.0, 20.5, 710.0, 1e300,
                   std::numeric_limits<double>::infinity(),
                   std::numeric_limits<double>::quiet_NaN()}) {
    xs.push_back(x);
    xs.push_back(-x);
  }
  while (xs.size() % 8 != 0) xs.push_back(0.3);
  const auto size = static_cast<Index>(xs.size());
  const Eigen::ArrayXd x = Eigen::Map<const Eigen::ArrayXd>(xs.data(), size);
  auto in_registers = [&x, size](auto packet) {
    using Packet = decltype(packet);
    constexpr Index lanes = Eigen::internal::unpacket_traits<Packet>::size;
    Eigen::ArrayXd z = x;
    for (Index i = 0; i < size; i += lanes) {
      const Packet entries = Eigen::internal::ploadu<Packet>(z.data() + i);
      Eigen::internal::pstoreu(z.data() + i, sbptt::detail::tanh_packet_double(entries));
    }
    return z;
  };
  std::vector<std::pair<const char*, Eigen::ArrayXd>> ways;
  ways.emplace_back("activate_in_place", x);
  sbptt::activate_in_place(Activation::Tanh, ways.back().second);
  ways.emplace_back("tanh_packet_double, a lone double", in_registers(double{}));
  ways.emplace_back("tanh_packet_double, this build's widest register",
                    in_registers(typename Eigen::internal::packet_traits<double>::type{}));
#if defined(EIGEN_VECTORIZE_SSE2)
  ways.emplace_back("tanh_packet_double, 2 lanes", in_registers(Eigen::internal::Packet2d{}));
#endif
  for (const auto& [way, z] : ways) {
    INFO(way);
    double worst = 0;
    for (Index i = 0; i < size; ++i) {
      const double expected = std::tanh(x(i));
      const double got = z(i);
      if (std::isnan(expected)) {
        REQUIRE(std::isnan(got));
        continue;
      }
      REQUIRE(std::signbit(got) == std::signbit(expected));
      if (expected != 0) worst = std::max(worst, std::abs(got - expected) / std::abs(expected));
      else REQUIRE(got == 0);
    }
    INFO("worst relative error " << worst);
    CHECK(worst < 1e-15);
  }
}
