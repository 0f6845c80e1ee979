// The engine with a real MLP controller: the Full sweep is the true gradient of the rollout
// loss (central finite differences), and training from a fixed seed is bitwise reproducible.
#include <catch2/catch.hpp>

#include "sbptt/bptt/engine.hpp"
#include "sbptt/bptt/losses.hpp"
#include "sbptt/core/finite_difference.hpp"
#include "sbptt/nn/init.hpp"
#include "sbptt/nn/network.hpp"
#include "sbptt/optim/adam.hpp"
#include "sbptt/sim/linear.hpp"
#include "sbptt/train/trainer.hpp"

using namespace sbptt;

namespace {

template <class Scalar = double>
using Sim = LinearSystem<Scalar>;
template <class Scalar = double>
using Loss = SquaredDistanceLoss<typename Sim<Scalar>::State>;

/// A 2-state, 1-control linear system (damped rotation plus input), or the scalar toy.
template <class Scalar = double>
Sim<Scalar> make_system(bool toy) {
  if (toy) return Sim<Scalar>::scalar(1, 1);
  typename Sim<Scalar>::StateJacobian a(2, 2);
  a << Scalar(0.95), Scalar(0.2), Scalar(-0.2), Scalar(0.95);
  typename Sim<Scalar>::ControlJacobian b(2, 1);
  b << 0, Scalar(0.3);
  return Sim<Scalar>(a, b);
}

template <class Scalar = double>
Network<Scalar> make_network(Index inputs, std::uint64_t seed) {
  auto network = Network<Scalar>::mlp(inputs, {6, 5}, 1);
  Rng rng(seed);
  glorot_uniform(network, rng);
  for (Index i = 0; i < network.num_params(); ++i)  // non-zero biases too
    if (network.params()(i) == 0) network.params()(i) = static_cast<Scalar>(0.1 * rng.uniform(-1, 1));
  return network;
}

}  // namespace

TEST_CASE("MLP controller: the Full gradient equals finite differences, horizons 1 to 8",
          "[bptt]") {
  for (bool toy : {true, false}) {
    const auto sim = make_system(toy);
    const Index n = sim.state_dim();
    for (auto timing : {LossTiming::Final, LossTiming::Continuous}) {
      for (Index m = 1; m <= 8; ++m) {
        auto network = make_network(n, static_cast<std::uint64_t>(10 * m + n));
        Sim<>::State target = Sim<>::State::Constant(n, toy ? 2.0 : 0.5);
        Engine engine(sim, network, Objective<Loss<>>{Loss<>{target}, timing, 0.5, 0.2}, m);
        Rng rng(static_cast<std::uint64_t>(m));
        Matrix<double> x0(n, 3);
        for (Index i = 0; i < x0.size(); ++i) x0(i) = rng.uniform(-1, 1);
        engine.forward(x0);
        Vector<double> g;
        engine.reverse(FlowMode::Full, g);

        const Vector<double> theta = network.params();
        auto loss_of = [&](const Vector<double>& p, Vector<double>& out) {
          network.params() = p;
          out.resize(1);
          out(0) = engine.evaluate(x0);
        };
        const Matrix<double> fd = finite_difference_jacobian<double>(loss_of, theta, 1).transpose();
        network.params() = theta;
        INFO((toy ? "toy" : "2-state") << ", horizon " << m
                                       << (timing == LossTiming::Final ? ", final" : ", continuous"));
        CHECK(relative_error<double>(g, fd) < 1e-7);
      }
    }
  }
}

TEST_CASE("MLP controller: the modified vector differs from the gradient only through K_n",
          "[bptt]") {
  // With an input-independent controller (all weights of the first layer zero), K_n = 0, so
  // every mode that keeps the physics path gives the true gradient.
  const auto sim = make_system(false);
  auto network = make_network(2, 3);
  network.params().head(2 * 6).setZero();  // first layer's weights (6 × 2)
  Sim<>::State target = Sim<>::State::Constant(2, 0.5);
  Engine engine(sim, network, Objective<Loss<>>{Loss<>{target}, LossTiming::Continuous}, 6);
  Matrix<double> x0(2, 2);
  x0 << 0.3, -0.5, 0.8, 0.1;
  const auto pair = engine.regular_and_modified(x0);
  CHECK(pair.modified.isApprox(pair.regular, 1e-14));
  CHECK(pair.comparison.cos_modified_regular == Approx(1.0));
}

TEMPLATE_TEST_CASE("training from a fixed seed gives bitwise-identical parameters",
                   "[bptt][train]", float, double) {
  using Scalar = TestType;
  const auto sim = make_system<Scalar>(false);
  Rng data_rng(5);
  Matrix<Scalar> train(2, 12), test(2, 4);
  for (Index i = 0; i < train.size(); ++i) train(i) = static_cast<Scalar>(data_rng.uniform(-1, 1));
  for (Index i = 0; i < test.size(); ++i) test(i) = static_cast<Scalar>(data_rng.uniform(-1, 1));
  auto run = [&](Method method) {
    auto network = make_network<Scalar>(2, 77);
    TrainerOptions options;
    options.method = method;
    options.batch = 4;
    options.clip = ClipMode::Norm;
    options.shuffle = true;
    options.shuffle_seed = 9;
    Trainer trainer(sim, network,
                    Objective<Loss<Scalar>>{Loss<Scalar>{Sim<Scalar>::State::Zero(2)},
                                            LossTiming::Continuous},
                    10, Adam<Scalar>(AdamOptions<Scalar>{Scalar(0.01)}), options);
    for (int epoch = 0; epoch < 5; ++epoch) trainer.train_epoch(train, test);
    return Vector<Scalar>(network.params());
  };
  for (Method method : {Method::Regular, Method::Combined}) {
    const Vector<Scalar> first = run(method), second = run(method);
    CHECK(first != make_network<Scalar>(2, 77).params());  // training moved the parameters
    CHECK(first == second);                                  // bit for bit
  }
}
