// Network::add_param_gradient of several steps at once (the engine's sweeps add two steps at a
// time): the same bits as one call per step in the same order, and the sum of each step's
// `backward` (round-off apart), for dense and convolution layers; too many steps or a record
// of another batch are refused before any work.
#include <catch2/catch.hpp>

#include <array>
#include <limits>
#include <span>
#include <vector>

#include "sbptt/core/finite_difference.hpp"
#include "sbptt/nn/init.hpp"
#include "sbptt/nn/network.hpp"
#include "support/networks.hpp"

using namespace sbptt;

namespace {

template <class S>
void check_several_steps(const Network<S>& net, std::uint64_t seed) {
  constexpr Index kBatch = 8;
  constexpr std::size_t kSteps = 3;
  Rng rng(seed);
  typename Network<S>::PackedWeights packed;
  net.pack(packed);
  std::array<typename Network<S>::Workspace, kSteps> workspaces;
  std::array<typename Network<S>::LayerAdjoints, kSteps> adjoints;
  std::vector<typename Network<S>::RecordedStep> steps;
  Vector<S> one_by_one = Vector<S>::Zero(net.num_params()), direct = one_by_one;
  for (std::size_t k = 0; k < kSteps; ++k) {
    Matrix<S> x(net.input_dim(), kBatch), dy(net.output_dim(), kBatch), y;
    for (Index i = 0; i < x.size(); ++i) x(i) = static_cast<S>(rng.uniform(-1, 1));
    for (Index i = 0; i < dy.size(); ++i) dy(i) = static_cast<S>(rng.uniform(-1, 1));
    net.forward(x, y, workspaces[k], packed);
    net.backward_inputs(workspaces[k], dy, nullptr, packed, adjoints[k]);
    net.add_param_gradient(workspaces[k], adjoints[k], one_by_one);
    net.backward(workspaces[k], dy, direct, nullptr, packed);
    steps.push_back({&workspaces[k], &adjoints[k]});
  }
  for (std::size_t count = 1; count <= kSteps; ++count) {
    INFO(count << " steps");
    Vector<S> together = Vector<S>::Zero(net.num_params()), expected = together;
    for (std::size_t k = 0; k < count; ++k) net.add_param_gradient(workspaces[k], adjoints[k], expected);
    net.add_param_gradient(std::span(steps.data(), count), together);
    CHECK(together == expected);
  }
  Vector<S> together = Vector<S>::Zero(net.num_params());
  net.add_param_gradient(std::span(steps.data(), kSteps), together);
  REQUIRE(direct.norm() > 0);
  CHECK(together == one_by_one);
  CHECK(relative_error<S>(together, direct) < 50 * std::numeric_limits<S>::epsilon());
}

}  // namespace

TEMPLATE_TEST_CASE("several steps: the parameter products of an MLP and of the quantum CNN, "
                   "step after step", "[nn]", float, double) {
  auto mlp = Network<TestType>::mlp(24, {100, 100}, 4);  // guidance's shapes
  auto cnn = testing::quantum_cnn<TestType>(16, 6);
  Rng rng(31);
  for (Network<TestType>* net : {&mlp, &cnn}) {
    glorot_uniform(*net, rng);
    check_several_steps(*net, rng.bits());
  }
}

TEST_CASE("several steps: too many steps and a record of another batch are refused", "[nn]") {
  const testing::SmallPackedMlp mlp(35);
  const Network<double>& net = mlp.net;
  const Network<double>::PackedWeights& packed = mlp.packed;
  Network<double>::Workspace ws, small;
  Matrix<double> y;
  net.forward(Matrix<double>::Ones(3, 4), y, ws, packed);
  net.forward(Matrix<double>::Ones(3, 2), y, small, packed);
  Network<double>::LayerAdjoints recorded, recorded_small;
  net.backward_inputs(ws, Matrix<double>::Ones(1, 4), nullptr, packed, recorded);
  net.backward_inputs(small, Matrix<double>::Ones(1, 2), nullptr, packed, recorded_small);
  Vector<double> grad = Vector<double>::Zero(net.num_params());
  const std::vector<Network<double>::RecordedStep> many(Network<double>::kMaxSteps + 1,
                                                        {&ws, &recorded});
  CHECK_THROWS_WITH(net.add_param_gradient(std::span(many), grad),
                    Catch::Contains("5 steps; expected at most 4"));
  // The second step's adjoints cover 2 samples, its workspace 4: refused before the first
  // step's products are added.
  const std::array<Network<double>::RecordedStep, 2> mixed{
      Network<double>::RecordedStep{&ws, &recorded}, {&ws, &recorded_small}};
  CHECK_THROWS_WITH(net.add_param_gradient(std::span(mixed), grad),
                    Catch::Contains("the adjoints do not cover"));
  CHECK(grad.isZero(0));
}
