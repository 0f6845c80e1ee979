// Network::add_param_gradient with per-sample scales: from adjoints recorded with a seed dY it
// adds the parameter products of dY·diag(s), which `backward` computes directly from that
// seed (round-off apart), for dense and convolution layers, with zero and negative scales;
// and a badly shaped call is refused before any work.
#include <catch2/catch.hpp>

#include <limits>

#include "sbptt/core/finite_difference.hpp"
#include "sbptt/nn/init.hpp"
#include "sbptt/nn/network.hpp"
#include "support/networks.hpp"

using namespace sbptt;

namespace {

template <class S>
void check_scaled_products(const Network<S>& net, std::uint64_t seed) {
  constexpr Index kBatch = 6;
  Rng rng(seed);
  Matrix<S> x(net.input_dim(), kBatch), dy(net.output_dim(), kBatch), scales(1, kBatch);
  for (Index i = 0; i < x.size(); ++i) x(i) = static_cast<S>(rng.uniform(-1, 1));
  for (Index i = 0; i < dy.size(); ++i) dy(i) = static_cast<S>(rng.uniform(-1, 1));
  scales << S(2.5), S(-0.75), S(0), S(1), S(-3), S(0.125);

  typename Network<S>::PackedWeights packed;
  net.pack(packed);
  typename Network<S>::Workspace ws;
  Matrix<S> y;
  net.forward(x, y, ws, packed);
  const Matrix<S> scaled_seed = dy * scales.row(0).asDiagonal();
  Vector<S> expected = Vector<S>::Zero(net.num_params());
  net.backward(ws, scaled_seed, expected, nullptr, packed);

  typename Network<S>::LayerAdjoints recorded, scaled;
  net.backward_inputs(ws, dy, nullptr, packed, recorded);
  Vector<S> grad = Vector<S>::Zero(net.num_params());
  net.add_param_gradient(ws, recorded, scales, scaled, grad);
  REQUIRE(expected.norm() > 0);
  CHECK(relative_error<S>(grad, expected) < 50 * std::numeric_limits<S>::epsilon());

  // It adds: a second call doubles the result, and the record is left as it was.
  net.add_param_gradient(ws, recorded, scales, scaled, grad);
  CHECK(relative_error<S>(grad, S(2) * expected) < 50 * std::numeric_limits<S>::epsilon());
  Vector<S> unscaled = Vector<S>::Zero(net.num_params()), direct = unscaled;
  net.add_param_gradient(ws, recorded, unscaled);
  net.backward(ws, dy, direct, nullptr, packed);
  CHECK(unscaled == direct);
}

}  // namespace

TEMPLATE_TEST_CASE("scaled seeds: an MLP's parameter products of dY·diag(s)", "[nn]", float,
                   double) {
  auto net = Network<TestType>::mlp(5, {24, 17}, 1);
  Rng rng(21);
  glorot_uniform(net, rng);
  check_scaled_products(net, 22);
  auto two_outputs = Network<TestType>::mlp(5, {24}, 2);  // the scales are per sample
  glorot_uniform(two_outputs, rng);
  check_scaled_products(two_outputs, 23);
}

TEMPLATE_TEST_CASE("scaled seeds: the quantum CNN's parameter products of dY·diag(s)", "[nn]",
                   float, double) {
  auto net = testing::quantum_cnn<TestType>(16, 6);
  Rng rng(24);
  glorot_uniform(net, rng);
  check_scaled_products(net, 25);
}

TEST_CASE("scaled seeds: badly shaped scales and a shared record are refused", "[nn]") {
  auto net = Network<double>::mlp(3, {4}, 1);
  Rng rng(26);
  glorot_uniform(net, rng);
  Network<double>::PackedWeights packed;
  net.pack(packed);
  Network<double>::Workspace ws;
  Matrix<double> y;
  net.forward(Matrix<double>::Ones(3, 4), y, ws, packed);
  Network<double>::LayerAdjoints recorded, scaled;
  net.backward_inputs(ws, Matrix<double>::Ones(1, 4), nullptr, packed, recorded);
  Vector<double> grad = Vector<double>::Zero(net.num_params());
  CHECK_THROWS_WITH(net.add_param_gradient(ws, recorded, Matrix<double>::Ones(1, 3), scaled, grad),
                    Catch::Contains("scales is 1 × 3, expected 1 × 4"));
  CHECK_THROWS_WITH(net.add_param_gradient(ws, recorded, Matrix<double>::Ones(2, 4), scaled, grad),
                    Catch::Contains("scales is 2 × 4"));
  CHECK_THROWS_WITH(
      net.add_param_gradient(ws, recorded, Matrix<double>::Ones(1, 4), recorded, grad),
      Catch::Contains("scaled is the recorded adjoints"));
  CHECK(grad.isZero(0));  // refused before any work
}
