// The combined update with one control per sample: both sweeps share one backward pass of the
// network (seed 1, scaled by each sweep's μ_n). Its g_R and g_M equal the lone Full and
// PhysicsOnly sweeps (each checked against finite differences elsewhere) to round-off, with
// truncation, a control regulariser and a continuous loss, and the network's backward runs
// once per step instead of twice.
#include <catch2/catch.hpp>

#include <atomic>
#include <limits>

#include "sbptt/bptt/engine.hpp"
#include "sbptt/bptt/losses.hpp"
#include "sbptt/core/finite_difference.hpp"
#include "sbptt/nn/init.hpp"
#include "sbptt/nn/network.hpp"
#include "support/networks.hpp"
#include "sbptt/objectives/cartpole.hpp"
#include "sbptt/objectives/quantum.hpp"
#include "sbptt/sim/cartpole.hpp"
#include "sbptt/sim/linear.hpp"
#include "sbptt/sim/schrodinger.hpp"

using namespace sbptt;

namespace {

/// A `Network` that counts its backward passes, whole and split. Atomic counts: on two threads
/// both threads run backward passes at once.
template <class Scalar>
struct CountingNetwork : Network<Scalar> {
  using Network<Scalar>::Network;
  mutable std::atomic<long> whole{0}, input_halves{0};

  void backward(const typename Network<Scalar>::Workspace& ws, const Matrix<Scalar>& dy,
                Vector<Scalar>& grad, Matrix<Scalar>* dx,
                const typename Network<Scalar>::PackedWeights& packed) const {
    ++whole;
    Network<Scalar>::backward(ws, dy, grad, dx, packed);
  }
  void backward(const typename Network<Scalar>::Workspace& ws, const Matrix<Scalar>& dy,
                Vector<Scalar>& grad, Matrix<Scalar>* dx) const {
    ++whole;
    Network<Scalar>::backward(ws, dy, grad, dx);
  }
  void backward_inputs(const typename Network<Scalar>::Workspace& ws, const Matrix<Scalar>& dy,
                       Matrix<Scalar>* dx, const typename Network<Scalar>::PackedWeights& packed,
                       typename Network<Scalar>::LayerAdjoints& adjoints) const {
    ++input_halves;
    Network<Scalar>::backward_inputs(ws, dy, dx, packed, adjoints);
  }
};

/// The pair against the lone sweeps over the same forward pass, within `tolerance` (relative to
/// the largest component), and the count of backward passes the pair took.
template <class Sim, class Net, class Loss>
void check_pair(const Sim& sim, Net& net, const Objective<Loss>& objective, Index steps,
                const Matrix<typename Sim::Scalar>& x0, Index threads, Index truncation,
                double tolerance) {
  using S = typename Sim::Scalar;
  INFO("threads " << threads << ", truncation " << truncation);
  Engine engine(sim, net, objective, steps);
  engine.set_threads(threads);
  net.whole = 0;
  net.input_halves = 0;
  const GradientPair<S> pair = engine.regular_and_modified(x0, truncation);
  CHECK(net.whole.load() == 0);
  CHECK(net.input_halves.load() == steps);  // one backward pass per step serves both sweeps

  Vector<S> full, physics;
  engine.forward(x0);
  const std::vector<double> full_norms = engine.reverse(FlowMode::Full, full, truncation).adjoint_norms;
  const std::vector<double> physics_norms =
      engine.reverse(FlowMode::PhysicsOnly, physics, truncation).adjoint_norms;
  REQUIRE(full.norm() > 0);
  REQUIRE(physics.norm() > 0);
  CHECK(relative_error<S>(pair.regular, full) < tolerance);
  CHECK(relative_error<S>(pair.modified, physics) < tolerance);
  CHECK(relative_error<S>(physics, full) > 10 * tolerance);  // so a swap would be seen
  for (std::size_t n = 0; n < full_norms.size(); ++n) {
    CHECK(pair.regular_diagnostics.adjoint_norms[n] ==
          Approx(full_norms[n]).epsilon(tolerance).margin(1e-30));
    CHECK(pair.modified_diagnostics.adjoint_norms[n] ==
          Approx(physics_norms[n]).epsilon(tolerance).margin(1e-30));
  }
}

}  // namespace

TEMPLATE_TEST_CASE("shared seed: cart pole with an MLP gives the lone sweeps' vectors",
                   "[bptt]", float, double) {
  using S = TestType;
  const double tolerance = 50 * std::numeric_limits<S>::epsilon();
  const CartPole<S, 2> sim;
  CountingNetwork<S> net(Network<S>::mlp(sim.state_dim(), {24, 24}, 1).layers());
  Rng rng(11);
  glorot_uniform(net, rng);
  const Matrix<S> x0 = cartpole_initial_states(sim, rng, 7);
  for (const Index threads : {1, 2})
    for (const Index truncation : {0, 9}) {
      check_pair(sim, net, cartpole_objective<S, 2>(), 30, x0, threads, truncation, tolerance);
    }
}

TEST_CASE("shared seed: quantum control with a CNN gives the lone sweeps' vectors", "[bptt]") {
  const Schrodinger1D<double, 16> sim;
  CountingNetwork<double> net(testing::quantum_cnn<double>(16, 6).layers());
  Rng rng(12);
  glorot_uniform(net, rng);
  const Matrix<double> x0 = sim.initial_states(rng, 5);
  for (const Index threads : {1, 2})
    check_pair(sim, net, quantum_objective(sim, 3), 12, x0, threads, 0,
               50 * std::numeric_limits<double>::epsilon());
}

TEST_CASE("shared seed: continuous loss with a control regulariser", "[bptt]") {
  using Sim = LinearSystem<double>;
  typename Sim::StateJacobian a(2, 2);
  a << 0.95, 0.2, -0.2, 0.95;
  typename Sim::ControlJacobian b(2, 1);
  b << 0, 0.3;
  const Sim sim(a, b);
  CountingNetwork<double> net(Network<double>::mlp(2, {6, 5}, 1).layers());
  Rng rng(13);
  glorot_uniform(net, rng);
  Matrix<double> x0(2, 4);
  for (Index i = 0; i < x0.size(); ++i) x0(i) = rng.uniform(-1, 1);
  using Loss = SquaredDistanceLoss<Sim::State>;
  const Objective<Loss> objective{Loss{Sim::State::Constant(2, 0.5)}, LossTiming::Continuous,
                                  0.5, 0.2};
  for (const Index threads : {1, 2})
    for (const Index truncation : {0, 3}) {
      check_pair(sim, net, objective, 8, x0, threads, truncation,
                 50 * std::numeric_limits<double>::epsilon());
    }
}
