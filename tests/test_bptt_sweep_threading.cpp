// Whether the batches whose sweeps meet the other thread at every step use the threads
// (`SweepThreading`): the timed decision's schedule against its closed form, fed made-up times
// (three probes on the threads, then three alone; the faster way is kept for 8 batches, twice
// as many after each probing that keeps it, up to 256; then it probes again), and the engine's
// batches against the way each policy says they ran, the first at a batch shape on the threads,
// and none on another thread with `Never`; the ways' names, both directions. That a trainer's
// option reaches its engine is tests/test_train_trainer.cpp's.
// That the results are the same bits either way is tests/test_bptt_threads.cpp's; that neither
// way allocates after the first batches, tests/test_bptt_no_malloc.cpp's.
#include <catch2/catch.hpp>

#include <atomic>
#include <limits>
#include <string>
#include <thread>
#include <utility>
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

/// Feeds one probing: the threaded way's times, then the other's; checks that it asks for them
/// in that order.
void probe(Decision& decision, const std::vector<double>& threaded_ns,
           const std::vector<double>& alone_ns) {
  for (int k = 0; k < kProbing; ++k) {
    const bool threaded = k < Decision::probes;
    INFO("probe " << k);
    REQUIRE(decision.next_threaded() == threaded);
    REQUIRE(decision.next_threaded(true));  // a batch at a new shape: on the threads
    const auto i = static_cast<std::size_t>(k % Decision::probes);
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
          "probes again sooner after it changes", "[bptt][threads]") {
  constexpr int shortest = Decision::shortest_between;
  Decision decision;
  // The threaded way's best (8) is slower than the other's (7), though its mean is not.
  probe(decision, {8, 9, 8}, {7, 20, 20});
  follow(decision, shortest, false);
  probe(decision, {8, 8, 8}, {7, 7, 7});  // the same way again: twice as long until the next
  follow(decision, 2 * shortest, false);
  // Now the threaded way's best is the faster: the shortest interval again.
  probe(decision, {5, 6, 6}, {6, 6, 6});
  follow(decision, shortest, true);
  probe(decision, {4, 4, 4}, {4, 5, 5});  // a tie: the threads are kept only when faster
  follow(decision, 3, false);
  CHECK(decision.first_at(8));
  CHECK(decision.first_at(8));  // until a batch of 8 finishes
  decision.finished_first_at(8, true);  // out of the schedule
  follow(decision, 1, false);
  CHECK_FALSE(decision.first_at(8));
  CHECK(decision.first_at(7));
  const SweepTally tally = decision.tally();
  CHECK(tally.threaded == 4 * Decision::probes + shortest + 1);
  CHECK(tally.alone == 4 * Decision::probes + 3 * shortest + 4);
}

TEST_CASE("sweep threading: while the choice holds the interval doubles up to the longest",
          "[bptt][threads]") {
  Decision decision;
  int between = Decision::shortest_between;
  int probings = 0;
  for (; between < Decision::longest_between; between *= 2, ++probings) {
    probe(decision, {5, 5, 5}, {6, 6, 6});
    follow(decision, between, true);
  }
  CHECK(probings == 5);  // 8, 16, 32, 64, 128
  for (int k = 0; k < 3; ++k) {
    probe(decision, {5, 5, 5}, {6, 6, 6});
    follow(decision, Decision::longest_between, true);
  }
  CHECK(decision.tally().alone == (probings + 3) * Decision::probes);
}

TEST_CASE("sweep threading: a first probing misled by a slow start is corrected within a few "
          "dozen batches", "[bptt][threads]") {
  // The cart pole's C batches on the family-26 host (docs/benchmark-runs.md, fifty-seventh
  // run): the first probing, in the engine's first epoch, timed the threads at 72.9 µs per
  // sample at best and the calling thread at 58.6; one probing later 41.4 and 60.6.
  Decision decision;
  probe(decision, {20, 20, 20}, {10, 10, 10});
  // From here on the threads take 5 per sample and the calling thread alone 10.
  int alone = 0;
  for (int k = 0; k < 64; ++k) {
    const bool threaded = decision.next_threaded();
    alone += threaded ? 0 : 1;
    decision.finished(threaded ? 5.0 : 10.0);
  }
  CHECK(alone <= 20);
  CHECK(decision.next_threaded());
}

TEST_CASE("sweep threading: Always and Never are never timed", "[bptt][threads]") {
  for (const SweepThreading policy : {SweepThreading::Always, SweepThreading::Never}) {
    const bool threaded = policy == SweepThreading::Always;
    Decision decision(policy);
    CHECK(decision.next_threaded(true) == threaded);
    constexpr int batches = kProbing + Decision::longest_between + 1;
    follow(decision, batches, threaded);
    CHECK(decision.tally().threaded == (threaded ? batches : 0));
    CHECK(decision.tally().alone == (threaded ? 0 : batches));
  }
}

TEST_CASE("sweep threading: the engine's batches, lone sweeps and pairs, run the way the policy "
          "says, the first at a batch shape on the threads when timed",
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
  const int batches = kProbing + 2;
  const int probes = Decision::probes;
  for (const SweepThreading policy :
       {SweepThreading::Always, SweepThreading::Never, SweepThreading::Timed}) {
    INFO("policy " << static_cast<int>(policy) << " (0 timed, 1 always, 2 never)");
    const bool timed = policy == SweepThreading::Timed;
    Engine engine(sim, net, cartpole_objective<double, 2>(), 20);
    engine.set_threads(2, never_split, policy);
    Vector<double> g;
    // Timed: the first batch (a new shape) on the threads, then a probing: 3 on the threads,
    // 3 alone; later batches go the faster way, not checked.
    for (int k = 0; k < batches; ++k) {
      INFO("lone batch " << k);
      const bool expected = policy == SweepThreading::Always || (timed && k <= probes);
      engine.forward(x0);
      const bool overlapped = engine.reverse(FlowMode::Full, g).params_overlapped;
      if (!timed || k <= 2 * probes) CHECK(overlapped == expected);
      // A second sweep over the same batch goes its way, and is neither timed nor counted.
      CHECK(engine.reverse(FlowMode::PhysicsOnly, g).params_overlapped == overlapped);
    }
    // With one control the pair shares its backward pass and, on the threads, splits its steps.
    // Its first batch is the first of its kind at this size.
    for (int k = 0; k < batches; ++k) {
      INFO("pair " << k);
      const bool expected = policy == SweepThreading::Always || (timed && k <= probes);
      const GradientPair<double> pair = engine.regular_and_modified(x0);
      if (!timed || k <= 2 * probes) {
        CHECK(pair.regular_diagnostics.params_overlapped == expected);
        CHECK(pair.modified_diagnostics.params_overlapped == expected);
      }
    }
    // A batch of a new shape, whatever the decision stands at.
    engine.forward(x0.leftCols(5));
    CHECK(engine.reverse(FlowMode::Full, g).params_overlapped ==
          (policy != SweepThreading::Never));
    const SweepTally tally = engine.sweep_tally();
    CHECK(tally.threaded + tally.alone == 2 * batches + 1);
    if (policy == SweepThreading::Always) CHECK(tally.alone == 0);
    if (policy == SweepThreading::Never) CHECK(tally.threaded == 0);
    if (timed) {  // the three first batches at a size and the probings', and later batches
      CHECK(tally.threaded >= 3 + kProbing);
      CHECK(tally.alone >= kProbing);
    }
  }
}

TEST_CASE("sweep threading: the first lone batch at a size runs on the threads though a pair "
          "ran at that size before", "[bptt][threads]") {
  const CartPole<double, 2> sim;
  auto net = Network<double>::mlp(sim.state_dim(), {16}, 1);
  Rng rng(7);
  glorot_uniform(net, rng);
  const Matrix<double> x0 = cartpole_initial_states(sim, rng, 6);
  Engine engine(sim, net, cartpole_objective<double, 2>(), 20);
  engine.set_threads(2, std::numeric_limits<double>::max(), SweepThreading::Timed);
  Vector<double> g;
  auto lone_overlapped = [&](const Matrix<double>& states) {
    engine.forward(states);
    return engine.reverse(FlowMode::Full, g).params_overlapped;
  };
  REQUIRE(lone_overlapped(x0));  // the first at its size
  for (int k = 0; k < Decision::probes; ++k) REQUIRE(lone_overlapped(x0));  // threaded probes
  // The lone decision's next batch is an alone probe; a pair at a new size comes first. The
  // lone batch at that size is still the first of its kind there, so it runs on the threads
  // (its hand-off's buffers are not the pair's); then the probing resumes.
  const Matrix<double> fewer = x0.leftCols(4);
  CHECK(engine.regular_and_modified(fewer).regular_diagnostics.params_overlapped);
  CHECK(lone_overlapped(fewer));
  CHECK_FALSE(lone_overlapped(fewer));
}

TEST_CASE("sweep threading: with Never no simulator call of a training batch leaves the calling "
          "thread, from the first batch on", "[bptt][threads]") {
  /// The cart pole stepped and differentiated sample by sample (its batched calls hidden), so
  /// that the engine, told to split every loop, would split them once timed; it notes any
  /// call made on another thread than the test's.
  struct Watched : CartPole<double, 2> {
    std::thread::id caller = std::this_thread::get_id();
    mutable std::atomic<int> elsewhere{0};
    void step_batch(const Matrix<double>&, const Matrix<double>&, Matrix<double>&) const = delete;
    void vjp_batch(const Matrix<double>&, const Matrix<double>&, const Matrix<double>&,
                   Matrix<double>*, Matrix<double>*) const = delete;
    void step(const State& x, const Control& u, State& x_next) const {
      note();
      CartPole<double, 2>::step(x, u, x_next);
    }
    void vjp(const State& x, const Control& u, const State& lambda, State* lambda_x,
             Control* lambda_u) const {
      note();
      CartPole<double, 2>::vjp(x, u, lambda, lambda_x, lambda_u);
    }
    void note() const {
      if (std::this_thread::get_id() != caller) elsewhere.fetch_add(1);
    }
  };
  const Watched sim;
  auto net = Network<double>::mlp(sim.state_dim(), {16}, 1);
  Rng rng(6);
  glorot_uniform(net, rng);
  const Matrix<double> x0 = cartpole_initial_states(sim, rng, 12);
  for (const SweepThreading policy : {SweepThreading::Never, SweepThreading::Always}) {
    INFO("policy " << static_cast<int>(policy) << " (1 always, 2 never)");
    sim.elsewhere = 0;
    Engine engine(sim, net, cartpole_objective<double, 2>(), 20);
    engine.set_threads(2, 0, policy);  // every per-sample loop split once timed
    Vector<double> g;
    // Always: the forward pass in parts, and the loops split, on the other thread too; but the
    // calling thread takes every part itself while the worker has not woken yet, so the
    // batches go on until a call is seen elsewhere (which shows that the watch sees them).
    const int most = policy == SweepThreading::Never ? 50 : 1000;
    for (int batches = 0;
         batches < most && (policy == SweepThreading::Never || sim.elsewhere.load() == 0);
         ++batches) {
      engine.forward(x0);
      engine.reverse(FlowMode::Full, g);
      engine.regular_and_modified(x0);
    }
    if (policy == SweepThreading::Never) CHECK(sim.elsewhere.load() == 0);
    if (policy == SweepThreading::Always) CHECK(sim.elsewhere.load() > 0);
  }
}

TEST_CASE("sweep threading: the ways parse and print", "[bptt][threads]") {
  const std::vector<std::pair<SweepThreading, std::string>> ways = {
      {SweepThreading::Timed, "timed"},
      {SweepThreading::Always, "always"},
      {SweepThreading::Never, "never"}};
  for (const auto& [way, text] : ways) {
    CHECK(to_string(way) == text);
    CHECK(parse_sweep_threading(text) == way);
  }
  for (const char* bad : {"Timed", "on", "", "always "}) {
    CHECK_THROWS_WITH(parse_sweep_threading(bad),
                      Catch::Contains(std::string("\"") + bad + "\"") &&
                          Catch::Contains("timed, always, never"));
  }
}
