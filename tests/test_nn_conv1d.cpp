// 1-D convolutions: closed-form forward values, PyTorch parameter order, the quantum
// controller's shape and parameter count, and finite-difference checks of both VJPs.
#include <catch2/catch.hpp>

#include <cmath>
#include <vector>

#include "support/test_data.hpp"
#include "sbptt/core/controller_check.hpp"
#include "sbptt/nn/init.hpp"
#include "sbptt/nn/network.hpp"
#include "support/networks.hpp"

using sbptt::Activation;
using sbptt::Conv1d;
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

TEMPLATE_TEST_CASE("conv1d forward matches a hand computation", "[nn][conv1d]", float, double) {
  using S = TestType;
  const double tol = std::is_same_v<S, float> ? 1e-5 : 1e-14;
  sbptt::Matrix<S> y;
  typename Network<S>::Workspace ws;

  SECTION("one channel, stride 2, trailing position dropped") {
    // L = 5, K = 2, s = 2: P = (5 − 2)/2 + 1 = 2 windows {0,1} and {2,3}; position 4 unused.
    Network<S> net({Conv1d{5, 1, 1, 2, 2, Activation::Identity}});
    REQUIRE(net.output_dim() == 2);
    net.params() << S(1), S(-1), S(0.5);
    sbptt::Matrix<S> x(5, 1);
    x << S(1), S(2), S(4), S(8), S(16);
    net.forward(x, y, ws);
    CHECK(static_cast<double>(y(0)) == Approx(1 - 2 + 0.5).margin(tol));
    CHECK(static_cast<double>(y(1)) == Approx(4 - 8 + 0.5).margin(tol));
  }
  SECTION("two input channels, two filters, tanh, position-major layout") {
    // Input positions (ch0, ch1): (1,2), (3,4), (5,6). Filter 0: ch0 (1, 2), ch1 (−1, 0.5),
    // bias 0.25. Filter 1: ch0 (0, 1), ch1 (1, 0), bias −1.
    Network<S> net({Conv1d{3, 2, 2, 2, 1, Activation::Tanh}});
    net.params() << S(1), S(2), S(-1), S(0.5), S(0), S(1), S(1), S(0), S(0.25), S(-1);
    sbptt::Matrix<S> x(6, 1);
    x << S(1), S(2), S(3), S(4), S(5), S(6);
    net.forward(x, y, ws);
    REQUIRE(y.rows() == 4);
    // Output row = position · 2 + filter.
    CHECK(static_cast<double>(y(0)) == Approx(std::tanh(1 + 6 - 2 + 2 + 0.25)).margin(tol));
    CHECK(static_cast<double>(y(1)) == Approx(std::tanh(3 + 2 - 1)).margin(tol));
    CHECK(static_cast<double>(y(2)) == Approx(std::tanh(3 + 10 - 4 + 3 + 0.25)).margin(tol));
    CHECK(static_cast<double>(y(3)) == Approx(std::tanh(5 + 4 - 1)).margin(tol));
  }
}

TEMPLATE_TEST_CASE("conv1d parameter order matches PyTorch Conv1d", "[nn][conv1d]", float,
                   double) {
  using S = TestType;
  // Every kernel width with its own window gather (1–5) and one past them (6).
  const Index kernel = GENERATE(1, 2, 3, 4, 5, 6);
  const Index length = 9, in_ch = 3, out_ch = 4, stride = 2;
  Network<S> net({Conv1d{length, in_ch, out_ch, kernel, stride, Activation::Identity}});
  const Index positions = (length - kernel) / stride + 1;
  REQUIRE(net.output_dim() == positions * out_ch);
  REQUIRE(net.num_params() == out_ch * in_ch * kernel + out_ch);
  const auto x = random_batch<S>(length * in_ch, 2, 5);
  sbptt::Matrix<S> y;
  typename Network<S>::Workspace ws;
  for (Index o = 0; o < out_ch; ++o) {
    for (Index c = 0; c < in_ch; ++c) {
      for (Index j = 0; j < kernel; ++j) {
        net.params().setZero();
        net.params()((o * in_ch + c) * kernel + j) = S(1);  // weight[o][c][j], row-major
        net.forward(x, y, ws);
        for (Index b = 0; b < 2; ++b) {
          for (Index p = 0; p < positions; ++p) {
            for (Index oo = 0; oo < out_ch; ++oo) {
              const S expected = oo == o ? x((p * stride + j) * in_ch + c, b) : S(0);
              CHECK(y(p * out_ch + oo, b) == expected);
            }
          }
        }
      }
    }
    net.params().setZero();
    net.params()(out_ch * in_ch * kernel + o) = S(1);  // bias[o] follows all weights
    net.forward(x, y, ws);
    for (Index p = 0; p < positions; ++p)
      for (Index oo = 0; oo < out_ch; ++oo) CHECK(y(p * out_ch + oo, 0) == S(oo == o ? 1 : 0));
  }
}

TEMPLATE_TEST_CASE("the quantum CNN has the paper's shapes and 11,701 parameters",
                   "[nn][conv1d]", float, double) {
  using S = TestType;
  const auto net = sbptt::testing::quantum_cnn<S>();
  CHECK(net.num_params() == 11701);
  CHECK(net.input_dim() == 64);
  CHECK(net.output_dim() == 1);
  CHECK(std::get<Conv1d>(net.layers()[0]).output_length() == 15);
  CHECK(std::get<Conv1d>(net.layers()[1]).output_length() == 7);
  CHECK(net.param_offset(1) == 60 * 2 * 3 + 60);
  CHECK(net.param_offset(2) == 420 + 60 * 60 * 3 + 60);
  sbptt::Matrix<S> y;
  typename Network<S>::Workspace ws;
  net.forward(random_batch<S>(64, 8, 1), y, ws);
  CHECK(y.rows() == 1);
  CHECK(y.cols() == 8);
}

TEST_CASE("conv1d backward equals central finite differences", "[nn][conv1d]") {
  std::uint64_t seed = 100;
  const std::vector<Conv1d> shapes = {
      {5, 1, 1, 2, 1, Activation::Identity}, {5, 1, 1, 2, 2, Activation::Tanh},
      {8, 3, 2, 3, 1, Activation::Tanh},     {8, 3, 2, 3, 2, Activation::Identity},
      {9, 2, 4, 3, 2, Activation::Tanh},     {7, 2, 3, 1, 1, Activation::Tanh},
      {6, 2, 3, 6, 1, Activation::Tanh},     {10, 2, 3, 2, 3, Activation::Tanh},
      {9, 2, 3, 4, 2, Activation::Tanh},     {11, 3, 2, 5, 3, Activation::Identity},
  };
  for (const auto& conv : shapes) {
    // Alone, followed by a dense layer (the flatten), and followed by another conv.
    std::vector<std::vector<sbptt::Layer>> stacks = {
        {conv},
        {conv, Dense{conv.output_dim(), 3, Activation::Tanh}},
    };
    if (conv.output_length() >= 2)
      stacks.push_back({conv, Conv1d{conv.output_length(), conv.out_channels, 2, 2, 1,
                                     Activation::Tanh}});
    for (const auto& layers : stacks) {
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
}

TEST_CASE("the quantum CNN backward equals central finite differences", "[nn][conv1d]") {
  auto net = sbptt::testing::quantum_cnn<double>();
  sbptt::Rng rng(42);
  sbptt::glorot_uniform(net, rng);
  for (const Index batch : {1, 5}) {
    INFO("batch " << batch);
    const auto check = sbptt::check_controller(net, random_batch<double>(64, batch, 7), 3);
    CHECK(check.worst() <= 1e-6);  // every path the engine may take
    CHECK(check.has_column_split == (batch > 1));  // a batch of 1 has no cut
  }
}

TEST_CASE("conv backward with dX == nullptr gives the same parameter gradient",
          "[nn][conv1d]") {
  auto net = sbptt::testing::quantum_cnn<double>();
  randomize(net, 11, 0.2);
  const auto x = random_batch<double>(64, 5, 12);
  const auto dy = random_batch<double>(1, 5, 13);
  sbptt::Matrix<double> y, dx;
  Network<double>::Workspace ws;
  net.forward(x, y, ws);
  Eigen::VectorXd with_dx = Eigen::VectorXd::Zero(net.num_params());
  Eigen::VectorXd without_dx = Eigen::VectorXd::Zero(net.num_params());
  net.backward(ws, dy, with_dx, &dx);
  net.backward(ws, dy, without_dx, nullptr);
  CHECK(with_dx == without_dx);
  CHECK(dx.rows() == 64);
  CHECK(dx.cols() == 5);
  // Positions 31 is past the last window of the first conv (windows start at 0, 2, …, 28).
  CHECK(dx.row(62).isZero(0));
  CHECK(dx.row(63).isZero(0));
  CHECK(dx.row(61).norm() > 0);
}

TEST_CASE("conv networks reject sizes that do not chain", "[nn][conv1d]") {
  using Catch::Contains;
  REQUIRE_THROWS_WITH(Network<double>({Conv1d{32, 2, 60, 3, 2}, Dense{421, 1}}),
                      Contains("expects 421 inputs") && Contains("produces 900"));
  // 15 × 60 = 900 = 30 × 30, but reinterpreting positions as channels is refused.
  REQUIRE_THROWS_WITH(Network<double>({Conv1d{32, 2, 60, 3, 2}, Conv1d{30, 30, 4, 3, 1}}),
                      Contains("expects 30 positions × 30 channels") &&
                          Contains("produces 15 × 60"));
  REQUIRE_THROWS_WITH(Network<double>({Conv1d{2, 1, 1, 3, 1}}),
                      Contains("length = 2") && Contains("kernel = 3"));
  REQUIRE_THROWS_WITH(Network<double>({Conv1d{8, 1, 1, 3, 0}}), Contains("stride = 0"));
  REQUIRE_THROWS_WITH(Network<double>({Conv1d{8, 0, 1, 3, 1}}), Contains("in_channels = 0"));
  // A dense layer may feed a conv: its output is read position-major.
  CHECK(Network<double>({Dense{4, 12}, Conv1d{6, 2, 3, 2, 2}}).output_dim() == 9);
}
