// Glorot-uniform initialisation: interval, fans, determinism, and the zeroed last kernel.
#include <catch2/catch.hpp>

#include <cmath>

#include "sbptt/nn/init.hpp"

using sbptt::Activation;
using sbptt::Conv1d;
using sbptt::Dense;
using sbptt::Index;
using sbptt::Network;

namespace {

// The weights of layer l as a contiguous segment of the flat vector.
template <class Scalar>
auto kernel_of(const Network<Scalar>& net, Index l) {
  return net.params().segment(net.param_offset(l),
                              sbptt::layer_weight_count(net.layers()[static_cast<std::size_t>(l)]));
}
template <class Scalar>
auto bias_of(const Network<Scalar>& net, Index l) {
  const auto& layer = net.layers()[static_cast<std::size_t>(l)];
  return net.params().segment(net.param_offset(l) + sbptt::layer_weight_count(layer),
                              sbptt::layer_num_params(layer) - sbptt::layer_weight_count(layer));
}

}  // namespace

TEST_CASE("Glorot limits follow the Keras fans", "[nn][init]") {
  CHECK(sbptt::glorot_limit(24, 100) == Approx(std::sqrt(6.0 / 124.0)));
  const auto dense = sbptt::glorot_fans(Dense{24, 100});
  CHECK(dense.first == 24);
  CHECK(dense.second == 100);
  const auto conv = sbptt::glorot_fans(Conv1d{32, 2, 60, 3, 2});
  CHECK(conv.first == 6);     // C_in · K
  CHECK(conv.second == 180);  // C_out · K
  REQUIRE_THROWS_AS(sbptt::glorot_limit(0, 3), sbptt::InvalidArgument);
}

TEMPLATE_TEST_CASE("Glorot-uniform weights fill ±limit, biases are zero", "[nn][init]", float,
                   double) {
  using S = TestType;
  Network<S> net({Conv1d{32, 2, 60, 3, 2, Activation::Tanh},
                  Conv1d{15, 60, 60, 3, 2, Activation::Tanh}, Dense{420, 1, Activation::Identity}});
  sbptt::Rng rng(42);
  sbptt::glorot_uniform(net, rng);
  const double limits[] = {std::sqrt(6.0 / (6 + 180)), std::sqrt(6.0 / (180 + 180)),
                           std::sqrt(6.0 / (420 + 1))};
  for (Index l = 0; l < 3; ++l) {
    INFO("layer " << l);
    const auto w = kernel_of(net, l);
    const S limit = static_cast<S>(limits[l]);
    CHECK(w.cwiseAbs().maxCoeff() <= limit);
    // Hundreds of draws reach close to the edge, so a wrong (too large) fan would show here.
    CHECK(w.cwiseAbs().maxCoeff() >= S(0.95) * limit);
    CHECK(std::abs(static_cast<double>(w.mean())) <= 0.1 * limits[l]);
    CHECK(bias_of(net, l).isZero(0));
  }
  CHECK(kernel_of(net, 2).cwiseAbs().minCoeff() > S(0));  // last kernel random by default
}

TEMPLATE_TEST_CASE("a fixed seed gives bitwise-identical parameters", "[nn][init]", float,
                   double) {
  using S = TestType;
  auto a = Network<S>::mlp(24, {100, 100}, 4);
  auto b = a;
  sbptt::Rng rng_a(7), rng_b(7), rng_c(8);
  sbptt::glorot_uniform(a, rng_a);
  sbptt::glorot_uniform(b, rng_b);
  CHECK(a.params() == b.params());
  sbptt::glorot_uniform(b, rng_c);
  CHECK(a.params() != b.params());
}

TEMPLATE_TEST_CASE("a zeroed last kernel makes the output exactly the last bias",
                   "[nn][init]", float, double) {
  using S = TestType;
  auto net = Network<S>::mlp(10, {100, 100}, 1);
  sbptt::Rng rng(42);
  sbptt::glorot_uniform(net, rng, {.zero_last_kernel = true});
  CHECK(kernel_of(net, 2).isZero(0));
  CHECK(bias_of(net, 2).isZero(0));
  CHECK(kernel_of(net, 0).cwiseAbs().maxCoeff() > S(0));
  CHECK(kernel_of(net, 1).cwiseAbs().maxCoeff() > S(0));

  sbptt::Rng data(3);
  sbptt::Matrix<S> x(10, 16);
  for (Index i = 0; i < x.size(); ++i) x(i) = static_cast<S>(data.uniform(-10, 10));
  sbptt::Matrix<S> y;
  typename Network<S>::Workspace ws;
  net.forward(x, y, ws);
  CHECK(y.isZero(0));

  // Earlier layers draw the same values with or without the option.
  auto full = Network<S>::mlp(10, {100, 100}, 1);
  sbptt::Rng rng2(42);
  sbptt::glorot_uniform(full, rng2);
  CHECK(full.params().head(net.param_offset(2)) == net.params().head(net.param_offset(2)));
}

TEST_CASE("fan overrides reproduce Keras' Conv2D (3, 2) fan for the quantum CNN",
          "[nn][init]") {
  Network<double> net({Conv1d{32, 2, 60, 3, 2, Activation::Tanh}, Dense{900, 1}});
  sbptt::Rng rng(1);
  sbptt::GlorotOptions options;
  options.fan_overrides = {std::pair<Index, Index>{6, 360}};
  sbptt::glorot_uniform(net, rng, options);
  const double limit = std::sqrt(6.0 / 366.0);
  CHECK(kernel_of(net, 0).cwiseAbs().maxCoeff() <= limit);
  CHECK(kernel_of(net, 0).cwiseAbs().maxCoeff() >= 0.95 * limit);
  CHECK(kernel_of(net, 1).cwiseAbs().maxCoeff() >= 0.95 * std::sqrt(6.0 / 901.0));
  options.fan_overrides.resize(3);
  REQUIRE_THROWS_WITH(sbptt::glorot_uniform(net, rng, options),
                      Catch::Contains("3 fan overrides"));
}
