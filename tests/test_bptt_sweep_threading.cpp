// Whether the sweeps whose threads meet at every step use the threads (`SweepThreading`): the
// timed decision's schedule against its closed form, fed made-up times (probes alternate, the
// threaded way first; the faster way is kept for `sweeps_between` batches; then it probes
// again), and the engine's batches against the way each policy says they ran. That the results
// are the same bits either way is tests/test_bptt_threads.cpp's.
#include <catch2/catch.hpp>

#include <limits>
#include <vector>

#include "sbptt/bptt/engine.hpp"
#include "sbptt/bptt/sweep_threading.hpp"
#include "sbptt/nn/init.hpp"
#include "sbptt/nn/network.hpp"
#include "sbptt/objectives/cartpole.hpp"
#include "sbptt/sim/cartpole.hpp"

using namespace sbptt;

namespace {

using Decision = detail::SweepThreadingDecision;
constexpr int kProbing = 2 * Decision::probes;

/// Feeds one probing: the threaded way's times and the other's, in the order they are asked
/// for; checks that the ways alternate, the threaded way first.
void probe(Decision& decision, const std::vector<double>& threaded_ns,
           const std::vector<double>& alone_ns) {
  for (int k = 0; k < kProbing; ++k) {
    const bool threaded = k % 2 == 0;
    INFO("probe " << k);
    REQUIRE(decision.next_threaded() == threaded);
    const auto i = static_cast<std::size_t>(k / 2);
    decision.finished(threaded ? threaded_ns[i] : alone_ns[i]);
  }
}

/// Feeds `count` decided sweeps, whose times must not matter, and checks their way.
void follow(Decision& decision, int count, bool threaded) {
  for (int k = 0; k < count; ++k) {
    INFO("decided sweep " << k);
    REQUIRE(decision.next_threaded() == threaded);
    decision.finished(k % 2 == 0 ? 0.0 : 1e9);
  }
}

}  // namespace

TEST_CASE("sweep threading: the timed decision keeps the faster way by its best probe, and "
          "probes again after sweeps_between batches", "[bptt][threads]") {
  Decision decision;
  // The threaded way's best (8) is slower than the other's (7), though its mean is not.
  probe(decision, {8, 9, 8}, {7, 20, 20});
  follow(decision, Decision::sweeps_between, false);
  // Now the threaded way's best is the faster.
  probe(decision, {5, 6, 6}, {6, 6, 6});
  follow(decision, Decision::sweeps_between, true);
  probe(decision, {4, 4, 4}, {4, 5, 5});  // a tie: the threads are kept only when faster
  follow(decision, 3, false);
  const SweepTally tally = decision.tally();
  CHECK(tally.threaded == 3 * Decision::probes + Decision::sweeps_between);
  CHECK(tally.alone == 3 * Decision::probes + Decision::sweeps_between + 3);
}

TEST_CASE("sweep threading: Always and Never are never timed", "[bptt][threads]") {
  for (const SweepThreading policy : {SweepThreading::Always, SweepThreading::Never}) {
    const bool threaded = policy == SweepThreading::Always;
    Decision decision(policy);
    follow(decision, kProbing + Decision::sweeps_between + 1, threaded);
    CHECK(decision.tally().threaded == (threaded ? kProbing + Decision::sweeps_between + 1 : 0));
    CHECK(decision.tally().alone == (threaded ? 0 : kProbing + Decision::sweeps_between + 1));
  }
}

TEST_CASE("sweep threading: the engine's batches, lone sweeps and pairs, run the way the policy "
          "says",
          "[bptt][threads]") {
  const CartPole<double, 2> sim;
  auto net = Network<double>::mlp(sim.state_dim(), {16}, 1);
  Rng rng(5);
  glorot_uniform(net, rng);
  const Matrix<double> x0 = cartpole_initial_states(sim, rng, 6);
  // The cart pole's VJPs are one call per batch (a BatchSimulator), and its loss seeds are
  // never split here, so a lone sweep on the threads hands its parameter products to the
  // second thread from the first sweep on.
  const double never_split = std::numeric_limits<double>::max();
  const int sweeps = kProbing + 2;
  for (const SweepThreading policy :
       {SweepThreading::Always, SweepThreading::Never, SweepThreading::Timed}) {
    INFO("policy " << static_cast<int>(policy) << " (0 timed, 1 always, 2 never)");
    Engine engine(sim, net, cartpole_objective<double, 2>(), 20);
    engine.set_threads(2, never_split, policy);
    Vector<double> g;
    for (int k = 0; k < sweeps; ++k) {
      INFO("lone sweep " << k);
      const bool expected = policy == SweepThreading::Always ||
                            (policy == SweepThreading::Timed && k < kProbing && k % 2 == 0);
      engine.forward(x0);
      const bool overlapped = engine.reverse(FlowMode::Full, g).params_overlapped;
      if (policy != SweepThreading::Timed || k < kProbing) CHECK(overlapped == expected);
      // A second sweep over the same batch goes its way, and is neither timed nor counted.
      CHECK(engine.reverse(FlowMode::PhysicsOnly, g).params_overlapped == overlapped);
    }
    // With one control the pair shares its backward pass and, on the threads, splits its steps.
    for (int k = 0; k < sweeps; ++k) {
      INFO("pair " << k);
      const bool expected = policy == SweepThreading::Always ||
                            (policy == SweepThreading::Timed && k < kProbing && k % 2 == 0);
      const GradientPair<double> pair = engine.regular_and_modified(x0);
      if (policy != SweepThreading::Timed || k < kProbing) {
        CHECK(pair.regular_diagnostics.params_overlapped == expected);
        CHECK(pair.modified_diagnostics.params_overlapped == expected);
      }
    }
    const SweepTally tally = engine.sweep_tally();
    CHECK(tally.threaded + tally.alone == 2 * sweeps);
    if (policy == SweepThreading::Always) CHECK(tally.alone == 0);
    if (policy == SweepThreading::Never) CHECK(tally.threaded == 0);
    if (policy == SweepThreading::Timed) {  // half of each probing, and each decided sweep's way
      CHECK(tally.threaded >= kProbing);
      CHECK(tally.alone >= kProbing);
    }
  }
}
