// check_gradient compares the engine's R gradient and the objective's ∂ℓ/∂x with central
// differences of the rollout loss: the shipped scenes pass (double and float), and a loss whose
// gradient is wrong, or a simulator whose VJP is wrong, fails. The engine also rejects a fixed-size
// State whose size disagrees with state_dim(), and a quantum or guidance loss made for a scene of
// another size. Quantum control runs the batched simulator path (step_batch / vjp_batch) of the
// engine.
#include <cmath>
#include <limits>

#include <catch2/catch.hpp>

#include "sbptt/bptt/gradient_check.hpp"
#include "sbptt/bptt/losses.hpp"
#include "sbptt/nn/init.hpp"
#include "sbptt/nn/network.hpp"
#include "sbptt/objectives/cartpole.hpp"
#include "sbptt/objectives/guidance.hpp"
#include "sbptt/objectives/quantum.hpp"
#include "sbptt/sim/cartpole.hpp"
#include "sbptt/sim/guidance_by_repulsion.hpp"
#include "sbptt/sim/linear.hpp"

using namespace sbptt;

namespace {

template <class Scalar>
Network<Scalar> small_network(Index in, Index out, std::uint64_t seed) {
  auto network = Network<Scalar>::mlp(in, {8, 8}, out);
  Rng rng(seed);
  glorot_uniform(network, rng);
  return network;
}

/// The paper's cart-pole loss with its gradient scaled by (1 + error).
struct WrongUprightLoss {
  double error = 0.01;
  double operator()(const CartPole<double, 1>::State& x, CartPole<double, 1>::State* grad) const {
    const double loss = CartPoleUprightLoss<double, 1>{}(x, grad);
    if (grad != nullptr) *grad *= 1 + error;
    return loss;
  }
};

/// The linear system with its VJP's control product scaled by (1 + error).
struct WrongVjp : LinearSystem<double, 2, 1> {
  using Base = LinearSystem<double, 2, 1>;
  double error = 0.01;
  explicit WrongVjp(Base base) : Base(std::move(base)) {}
  void vjp(const State& x, const Control& u, const State& l, State* lx, Control* lu) const {
    Base::vjp(x, u, l, lx, lu);
    if (lu != nullptr) *lu *= 1 + error;
  }
};

LinearSystem<double, 2, 1> oscillator() {
  Eigen::Matrix2d a;
  a << 1.0, 0.1, -0.1, 0.98;
  return LinearSystem<double, 2, 1>(a, Eigen::Vector2d(0.005, 0.1));
}

}  // namespace

TEST_CASE("check_gradient passes the shipped scenes in double", "[bptt][gradient_check]") {
  SECTION("cart pole, final-state loss") {
    const CartPole<double, 1> sim;
    auto network = small_network<double>(4, 1, 1);
    Rng rng(2);
    const auto x0 = cartpole_initial_states(sim, rng, 3);
    const auto check = check_gradient(sim, network, cartpole_objective<double, 1>(), 20, x0);
    INFO("R " << check.regular_error << ", state loss " << check.state_loss_error);
    CHECK(check.parameters_checked == 64);
    CHECK(check.worst() < 1e-5);
  }
  SECTION("guidance, continuous loss with the control regulariser") {
    GuidanceOptions options;
    options.steps = 15;
    const GuidanceByRepulsion<double, 2, 4> sim(options);
    auto network = small_network<double>(24, 4, 3);
    Rng rng(4);
    const auto x0 = guidance_initial_states(sim, rng, 2);
    const auto check = check_gradient(sim, network, guidance_objective(sim, 0.01), 15, x0,
                                      {.max_parameters = 500});
    INFO("R " << check.regular_error << ", state loss " << check.state_loss_error);
    CHECK(check.parameters_checked == network.num_params());
    CHECK(check.worst() < 1e-5);
  }
  SECTION("quantum control, continuous loss, the batched simulator") {
    const Schrodinger1D<double, 8> sim;
    static_assert(BatchSimulator<Schrodinger1D<double, 8>>);
    auto network = small_network<double>(16, 1, 6);
    Rng rng(7);
    const auto x0 = sim.initial_states(rng, 19);  // two full blocks of 8 lanes, a partial one
    const auto check = check_gradient(sim, network, quantum_objective(sim, 3), 12, x0,
                                      {.max_parameters = 500});
    INFO("R " << check.regular_error << ", state loss " << check.state_loss_error);
    CHECK(check.parameters_checked == network.num_params());
    CHECK(check.worst() < 1e-5);
  }
}

TEST_CASE("check_gradient passes a scene in float at its documented tolerance",
          "[bptt][gradient_check][float]") {
  Eigen::Matrix2f a;
  a << 1.0f, 0.1f, -0.1f, 0.98f;
  const LinearSystem<float, 2, 1> sim(a, Eigen::Vector2f(0.005f, 0.1f));
  auto network = small_network<float>(2, 1, 5);
  Matrix<float> x0(2, 3);
  x0 << 1.0f, -0.5f, 0.3f, 0.2f, 0.8f, -1.0f;
  using Loss = SquaredDistanceLoss<Eigen::Vector2f>;
  Objective<Loss> objective{Loss{Eigen::Vector2f::Zero()}, LossTiming::Continuous, 0.1, 0.01};
  const auto check = check_gradient(sim, network, objective, 10, x0);
  INFO("R " << check.regular_error << ", state loss " << check.state_loss_error);
  CHECK(check.worst() < 5e-2f);
}

TEST_CASE("check_gradient fails a wrong loss gradient and a wrong VJP", "[bptt][gradient_check]") {
  SECTION("the loss gradient is 1% too large") {
    const CartPole<double, 1> sim;
    auto network = small_network<double>(4, 1, 1);
    Rng rng(2);
    const auto x0 = cartpole_initial_states(sim, rng, 3);
    Objective<WrongUprightLoss> objective;
    const auto check = check_gradient(sim, network, objective, 20, x0);
    CHECK(check.state_loss_error == Approx(0.01).epsilon(1e-3));
    CHECK(check.regular_error == Approx(0.01).epsilon(1e-3));  // g is linear in the seed
  }
  SECTION("the control product of the VJP is 1% too large") {
    const WrongVjp sim(oscillator());
    auto network = small_network<double>(2, 1, 6);
    Matrix<double> x0(2, 2);
    x0 << 1.0, -0.5, 0.3, 0.2;
    using Loss = SquaredDistanceLoss<Eigen::Vector2d>;
    const auto check = check_gradient(sim, network, Objective<Loss>{Loss{Eigen::Vector2d::Zero()}},
                                      10, x0);
    CHECK(check.state_loss_error < 1e-8);
    CHECK(check.regular_error > 1e-3);
  }
}

TEST_CASE("check_gradient leaves the parameters exactly as they were", "[bptt][gradient_check]") {
  const CartPole<double, 1> sim;
  auto network = small_network<double>(4, 1, 7);
  const Vector<double> before = network.params();
  Rng rng(8);
  (void)check_gradient(sim, network, cartpole_objective<double, 1>(), 5,
                       cartpole_initial_states(sim, rng, 2));
  CHECK(network.params() == before);
}

TEST_CASE("The engine rejects a fixed-size State whose size disagrees with state_dim()",
          "[bptt][engine]") {
  // A State of 4 numbers with state_dim() = 3 would read past the trajectory's rows.
  struct Mismatched : LinearSystem<double, 4, 1> {
    Mismatched() : LinearSystem<double, 4, 1>(Eigen::Matrix4d::Identity(), Eigen::Vector4d::Ones()) {}
    [[nodiscard]] Index state_dim() const { return 3; }
  };
  const Mismatched sim;
  auto network = small_network<double>(3, 1, 9);
  using Loss = SquaredDistanceLoss<Eigen::Vector4d>;
  using E = Engine<Mismatched, Network<double>, Loss>;
  const Objective<Loss> objective{Loss{Eigen::Vector4d::Zero()}};
  CHECK_THROWS_WITH(E(sim, network, objective, 5),
                    Catch::Contains("State holds 4 numbers but its state_dim() = 3"));
}

TEST_CASE("The engine refuses a quantum or guidance objective made for another size of scene "
          "when it is built", "[bptt][engine]") {
  // With run-time sizes the loss and the simulator are built apart, and nothing else ties them.
  using Quantum = Schrodinger1D<double, Eigen::Dynamic>;
  const Quantum grid8(8), grid6(6);
  auto quantum_network = small_network<double>(grid8.state_dim(), 1, 3);
  const auto made_for_six = quantum_objective(grid6, 2);
  REQUIRE_THROWS_AS((Engine(grid8, quantum_network, made_for_six, 4)), InvalidArgument);
  REQUIRE_THROWS_WITH((Engine(grid8, quantum_network, made_for_six, 4)),
                      Catch::Contains("QuantumInfidelityLoss") && Catch::Contains("12 entries") &&
                          Catch::Contains("state_dim = 16"));
  Engine quantum_fits(grid8, quantum_network, quantum_objective(grid8, 2), 4);
  Rng rng(5);
  CHECK(std::isfinite(quantum_fits.forward(grid8.initial_states(rng, 2))));

  using Guidance = GuidanceByRepulsion<double, Eigen::Dynamic, Eigen::Dynamic>;
  const Guidance three_evaders(2, 3), four_evaders(2, 4);
  auto guidance_network = small_network<double>(three_evaders.state_dim(),
                                                three_evaders.control_dim(), 4);
  const auto made_for_four = guidance_objective(four_evaders, 0.0);
  REQUIRE_THROWS_AS((Engine(three_evaders, guidance_network, made_for_four, 4)),
                    InvalidArgument);
  REQUIRE_THROWS_WITH((Engine(three_evaders, guidance_network, made_for_four, 4)),
                      Catch::Contains("GuidanceLoss") && Catch::Contains("24 numbers") &&
                          Catch::Contains("state_dim = 20"));
  Engine guidance_fits(three_evaders, guidance_network, guidance_objective(three_evaders, 0.0), 4);
  CHECK(std::isfinite(guidance_fits.forward(guidance_initial_states(three_evaders, rng, 2))));
}

TEST_CASE("The engine refuses a squared-distance target that is not finite when it is built",
          "[bptt][engine]") {
  // Before, a NaN target trained until the first batch stopped on a non-finite loss.
  const auto sim = oscillator();
  auto network = small_network<double>(2, 1, 6);
  using Loss = SquaredDistanceLoss<Eigen::Vector2d>;
  for (const double bad : {std::numeric_limits<double>::quiet_NaN(),
                           -std::numeric_limits<double>::infinity()}) {
    const Objective<Loss> objective{Loss{Eigen::Vector2d(0.0, bad)}};
    REQUIRE_THROWS_AS((Engine(sim, network, objective, 4)), InvalidArgument);
    REQUIRE_THROWS_WITH((Engine(sim, network, objective, 4)),
                        Catch::Contains("SquaredDistanceLoss: the target's entry 1 is ") &&
                            Catch::Contains("; expected finite numbers"));
  }
  const Objective<Loss> finite{Loss{Eigen::Vector2d(0.0, 1.0)}};
  CHECK_NOTHROW(Engine(sim, network, finite, 4));
}

TEST_CASE("check_gradient reports a NaN loss gradient as NaN", "[bptt][gradient_check]") {
  const CartPole<double, 1> sim;
  auto network = small_network<double>(4, 1, 1);
  Rng rng(2);
  const auto x0 = cartpole_initial_states(sim, rng, 3);
  Objective<WrongUprightLoss> objective;
  objective.state_loss.error = std::numeric_limits<double>::quiet_NaN();
  const auto check = check_gradient(sim, network, objective, 20, x0);
  CHECK(std::isnan(check.state_loss_error));
  CHECK(std::isnan(check.worst()));
}

TEST_CASE("check_gradient's worst() is NaN when either error is NaN", "[bptt][gradient_check]") {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  sbptt::GradientCheck<double> check;
  check.state_loss_error = nan;  // second: std::max(0, NaN) would drop it
  CHECK(std::isnan(check.worst()));
  check.state_loss_error = 0;
  check.regular_error = nan;
  CHECK(std::isnan(check.worst()));
}
