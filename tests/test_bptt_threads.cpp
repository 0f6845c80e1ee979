// Threads change the speed, never the numbers: the loss, g_R, g_M, every diagnostic, the
// evaluation of a set, its non-finite report, and the parameters after a few Trainer epochs
// are bitwise identical for 1, 2 and 3 threads (cart pole with an MLP, guidance, and quantum
// control with a CNN; batches and sets whose sizes do not divide evenly; the pair also
// truncated), whether the per-sample loops are split, a lone sweep hands its parameter
// products to a second thread, or the pair with one control splits its steps between two.
#include <catch2/catch.hpp>

#include <cmath>
#include <limits>
#include <stdexcept>
#include <utility>
#include <vector>

#include "sbptt/objectives/cartpole.hpp"
#include "sbptt/objectives/guidance.hpp"
#include "sbptt/objectives/quantum.hpp"
#include "sbptt/bptt/engine.hpp"
#include "sbptt/bptt/losses.hpp"
#include "sbptt/core/finite_difference.hpp"
#include "sbptt/nn/init.hpp"
#include "sbptt/nn/network.hpp"
#include "support/networks.hpp"
#include "sbptt/optim/adam.hpp"
#include "sbptt/sim/cartpole.hpp"
#include "sbptt/sim/guidance_by_repulsion.hpp"
#include "sbptt/sim/linear.hpp"
#include "sbptt/sim/schrodinger.hpp"
#include "sbptt/train/trainer.hpp"

using namespace sbptt;

namespace {

template <class Scalar>
struct PairRecord {
  Scalar loss;
  Vector<Scalar> regular, modified;
  std::vector<double> regular_norms, modified_norms;
  double cos, agree;
};

void check_same(const SweepDiagnostics& a, const SweepDiagnostics& b) {
  CHECK(a.grad_norm2 == b.grad_norm2);
  CHECK(a.adjoint_norms == b.adjoint_norms);
  CHECK(a.first_non_finite.has_value() == b.first_non_finite.has_value());
}

/// Everything an engine reports for one batch, and training results, at `threads`.
template <class Sim, class Net, class Objective>
void check_thread_independence(const Sim& sim, const Net& initial, const Objective& objective,
                               Index steps, const Matrix<typename Sim::Scalar>& train,
                               const Matrix<typename Sim::Scalar>& test, Index batch) {
  using S = typename Sim::Scalar;
  const Matrix<S> x0 = train.leftCols(batch);
  std::vector<GradientPair<S>> pairs, truncated_pairs;
  std::vector<Vector<S>> full, physics, stopped, trained_r, trained_c;
  std::vector<S> evaluations;
  std::vector<bool> overlapped;
  // 1 thread, then 2 and 3 threads with every per-sample loop split (threshold 0), with the
  // default threshold (cheap loops stay on one thread), and with no loop ever split, which
  // makes every lone sweep after the first hand its parameter products to a second thread;
  // those sweeps always on the threads, then as timed (some on the threads, some not), and
  // never.
  const double never = std::numeric_limits<double>::max();
  struct Setting {
    Index threads;
    double split;
    SweepThreading sweeps;
  };
  const auto always = SweepThreading::Always, timed = SweepThreading::Timed;
  const std::vector<Setting> settings = {
      {1, 4000, timed},    {2, 0, always},     {3, 0, always},
      {2, 4000, always},   {2, never, always}, {3, never, always},
      {2, 0, timed},       {2, never, timed},  {2, never, SweepThreading::Never}};
  for (const auto& [threads, split, sweeps] : settings) {
    Net net = initial;
    Engine engine(sim, net, objective, steps);
    engine.set_threads(threads, split, sweeps);
    REQUIRE(engine.threads() == threads);
    GradientPair<S> pair;
    engine.regular_and_modified(x0, pair);
    pairs.push_back(pair);
    engine.regular_and_modified(x0, pair, steps / 4);  // truncated, for variety
    truncated_pairs.push_back(pair);
    Vector<S> g;
    engine.forward(x0);
    engine.reverse(FlowMode::Full, g);
    full.push_back(g);
    engine.reverse(FlowMode::PhysicsOnly, g, steps / 3);  // truncated, for variety
    physics.push_back(g);
    overlapped.push_back(engine.reverse(FlowMode::Stopped, g).params_overlapped);
    stopped.push_back(g);
    evaluations.push_back(engine.evaluate(test));

    for (const Method method : {Method::Regular, Method::Combined}) {
      Net trained = initial;
      TrainerOptions options;
      options.method = method;
      options.batch = batch;
      options.clip = ClipMode::Norm;
      options.threads = threads;
      Trainer trainer(sim, trained, objective, steps, Adam<S>(AdamOptions<S>{S(1e-3)}), options);
      trainer.engine().set_threads(threads, split, sweeps);
      for (int epoch = 0; epoch < 2; ++epoch) {
        const EpochRecord record = trainer.train_epoch(train, test);
        REQUIRE(std::isfinite(record.test_loss.value()));
      }
      (method == Method::Regular ? trained_r : trained_c).push_back(trained.params());
    }
  }
  for (std::size_t t = 1; t < pairs.size(); ++t) {
    const Setting& setting = settings[t];
    INFO("threads " << setting.threads << ", split above " << setting.split
                    << " ns, sweeps " << static_cast<int>(setting.sweeps)
                    << " (0 timed, 1 always, 2 never), against 1 thread");
    CHECK(pairs[t].loss == pairs[0].loss);
    CHECK(pairs[t].regular == pairs[0].regular);
    CHECK(pairs[t].modified == pairs[0].modified);
    CHECK(pairs[t].combined == pairs[0].combined);
    CHECK(truncated_pairs[t].regular == truncated_pairs[0].regular);
    CHECK(truncated_pairs[t].modified == truncated_pairs[0].modified);
    check_same(truncated_pairs[t].modified_diagnostics, truncated_pairs[0].modified_diagnostics);
    check_same(pairs[t].regular_diagnostics, pairs[0].regular_diagnostics);
    check_same(pairs[t].modified_diagnostics, pairs[0].modified_diagnostics);
    CHECK(pairs[t].comparison.cos_modified_regular == pairs[0].comparison.cos_modified_regular);
    CHECK(pairs[t].comparison.agree_fraction == pairs[0].comparison.agree_fraction);
    CHECK(full[t] == full[0]);
    CHECK(physics[t] == physics[0]);
    CHECK(stopped[t] == stopped[0]);
    CHECK(evaluations[t] == evaluations[0]);
    CHECK(trained_r[t] == trained_r[0]);
    CHECK(trained_c[t] == trained_c[0]);
    if (setting.split == never && setting.sweeps == always)
      CHECK(overlapped[t]);  // so the hand-off was compared
    if (setting.split == 0 || setting.sweeps == SweepThreading::Never)
      CHECK_FALSE(overlapped[t]);
  }
  CHECK_FALSE(overlapped[0]);
  // The pair's g_C, formed in the comparison's pass, is combine(g_M, g_R).
  Vector<S> combined;
  combine(pairs[0].modified, pairs[0].regular, combined);
  CHECK(pairs[0].combined == combined);
  // The sweeps of the pair equal the single sweeps (bit for bit when they run apart, to
  // round-off when one control lets them share the network's backward pass), and training
  // moved the parameters.
  if (sim.control_dim() == 1) {
    CHECK(relative_error<S>(pairs[0].regular, full[0]) <
          1000 * std::numeric_limits<S>::epsilon());
  } else {
    CHECK(pairs[0].regular == full[0]);
  }
  CHECK(trained_r[0] != initial.params());
  CHECK(trained_c[0] != trained_r[0]);
}

template <class Sim>
void check_quantum_thread_independence(const Sim& sim) {
  using S = typename Sim::Scalar;
  Network<S> net = testing::quantum_cnn<S>(16, 12);
  Rng rng(44);
  glorot_uniform(net, rng);
  const Matrix<S> train = sim.initial_states(rng, 16);
  const Matrix<S> test = sim.initial_states(rng, 40);
  check_thread_independence(sim, net, quantum_objective(sim, 4), 16, train, test, 8);
}

template <class Scalar>
Network<Scalar> seeded_mlp(Index inputs, Index outputs, std::uint64_t seed) {
  auto net = Network<Scalar>::mlp(inputs, {24, 24}, outputs);
  Rng rng(seed);
  glorot_uniform(net, rng);
  return net;
}

}  // namespace

TEMPLATE_TEST_CASE("threads: cart pole results are bitwise identical for 1, 2 and 3 threads",
                   "[bptt][threads]", float, double) {
  using S = TestType;
  const CartPole<S, 2> sim;
  Rng rng(42);
  const Matrix<S> train = cartpole_initial_states(sim, rng, 21);  // batches of 5: 5,5,5,5,1
  const Matrix<S> test = cartpole_initial_states(sim, rng, 70);   // chunks of 32: 32,32,6
  check_thread_independence(sim, seeded_mlp<S>(sim.state_dim(), 1, 7),
                            cartpole_objective<S, 2>(), 30, train, test, 5);
  // The physical model steps its batch column by column in scalar code: the pattern that gave
  // other last bits per thread count where a path had its own inlined copy (docs/design.md).
  sbptt::CartPoleOptions options;
  options.model = sbptt::CartPoleModel::Physical;
  const CartPole<S, 2> coupled(options);
  check_thread_independence(coupled, seeded_mlp<S>(coupled.state_dim(), 1, 7),
                            cartpole_objective<S, 2>(), 30, train, test, 5);
}

// In float guidance is a PairedBatchSimulator: on one thread the pair's sweeps then share one
// `vjp_batch_pair` call per step (ReverseSweeps::pair_in_step), against a `vjp_batch` call of
// B columns each on two threads.
TEMPLATE_TEST_CASE("threads: guidance (continuous loss, regulariser) is bitwise identical",
                   "[bptt][threads]", float, double) {
  using S = TestType;
  GuidanceOptions options;
  options.steps = 20;
  const GuidanceByRepulsion<S, 2, 4> sim(options);
  Rng rng(43);
  const Matrix<S> train = guidance_initial_states(sim, rng, 16);
  const Matrix<S> test = guidance_initial_states(sim, rng, 40);
  check_thread_independence(sim, seeded_mlp<S>(sim.state_dim(), sim.control_dim(), 8),
                            guidance_objective(sim, 0.1), 20, train, test, 8);
}

TEST_CASE("threads: quantum control with a CNN is bitwise identical", "[bptt][threads]") {
  check_quantum_thread_independence(Schrodinger1D<float, 16>());
}

// A grid size known only at run time (`quantum --nx` other than 32) takes the per-sample step
// and VJP instead of the lanes of a fixed Nx. (This passed before the quantum program's
// results depended on --threads too: that depended on how GCC compiled the program, and
// tests/programs/test_task_programs.cpp is its regression test.)
TEMPLATE_TEST_CASE("threads: quantum control on a run-time grid is bitwise identical",
                   "[bptt][threads]", float, double) {
  check_quantum_thread_independence(Schrodinger1D<TestType, Eigen::Dynamic>(16));
}

TEST_CASE("threads: evaluate reports the same first non-finite value for any thread count",
          "[bptt][threads]") {
  const CartPole<double, 1> sim;
  const auto net = seeded_mlp<double>(sim.state_dim(), 1, 9);
  Rng rng(45);
  Matrix<double> set = cartpole_initial_states(sim, rng, 80);
  // Sample 40 (second chunk) overflows to +inf in its state x_1; sample 70 (third chunk) has a
  // NaN angle in x_0. x_0 comes before x_1 in rollout order, so the report is sample 70's
  // state at step 0 (as `forward` reports it), whichever chunk finishes first.
  set(0, 40) = 1.79e308;
  set(1, 40) = 1e308;
  set(2, 70) = std::numeric_limits<double>::quiet_NaN();
  std::vector<NonFinite> reports;
  std::vector<double> losses;
  for (const Index threads : {1, 2, 3}) {
    Engine engine(sim, net, cartpole_objective<double, 1>(), 10);
    engine.set_threads(threads, 0);
    losses.push_back(engine.evaluate(set));
    REQUIRE(engine.forward_non_finite());
    reports.push_back(*engine.forward_non_finite());
  }
  CHECK(std::isnan(losses[0]));
  for (const auto& report : reports) {
    CHECK(report.quantity == Quantity::State);
    CHECK(report.step == 0);
    CHECK(report.sample == 70);
  }
}

TEST_CASE("threads: forward reports the first non-finite value in rollout order for any thread "
          "count", "[bptt][threads]") {
  // x_{n+1} = 2 x_n + u with a bounded u (tanh, then a linear layer): x_0 = 1e306 first
  // overflows at x_8, 1e308 at x_1. With 2 and 3 threads the batch of 12 is rolled out in
  // parts [0, 6), [6, 12) and [0, 4), [4, 8), [8, 12), each to the end: a later part's earlier
  // step must win, and at one place the lower sample, as in one rollout of the whole batch.
  const auto sim = LinearSystem<double, 1, 1>::scalar(2.0, 1.0);
  auto net = Network<double>::mlp(1, {4}, 1);
  Rng rng(3);
  glorot_uniform(net, rng);
  using State = LinearSystem<double, 1, 1>::State;
  const Objective<SquaredDistanceLoss<State>> objective{{State::Zero()}};
  struct Setup {
    std::vector<std::pair<Index, double>> starts;
    Quantity quantity;
    Index step, sample;
  };
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const std::vector<Setup> setups = {
      {{{2, 1e306}, {10, 1e308}}, Quantity::State, 1, 10},  // the last part's x_1
      {{{9, 1e308}, {1, 1e308}}, Quantity::State, 1, 1},    // both at x_1: sample 1
      {{{1, 1e308}, {7, nan}}, Quantity::State, 0, 7},      // x_0 before x_1
  };
  for (const Setup& setup : setups) {
    Matrix<double> x0 = Matrix<double>::Constant(1, 12, 0.5);
    for (const auto& [sample, value] : setup.starts) x0(0, sample) = value;
    for (const auto& [threads, split] : std::vector<std::pair<Index, double>>{
             {1, 4000}, {2, 0}, {2, 4000}, {3, 0}, {3, 4000}}) {
      INFO("threads " << threads << ", expected sample " << setup.sample);
      Engine engine(sim, net, objective, 10);
      engine.set_threads(threads, split);
      CHECK_FALSE(std::isfinite(engine.forward(x0)));
      REQUIRE(engine.forward_non_finite());
      CHECK(engine.forward_non_finite()->quantity == setup.quantity);
      CHECK(engine.forward_non_finite()->step == setup.step);
      CHECK(engine.forward_non_finite()->sample == setup.sample);
    }
  }
}

TEST_CASE("threads: bad settings are rejected with a clear message", "[bptt][threads]") {
  const CartPole<double, 1> sim;
  const auto net = seeded_mlp<double>(sim.state_dim(), 1, 9);
  Engine engine(sim, net, cartpole_objective<double, 1>(), 10);
  CHECK_THROWS_WITH(engine.set_threads(0), Catch::Contains("threads = 0"));
  CHECK_THROWS_WITH(engine.set_threads(2, -1.0), Catch::Contains("split_above_ns = -1"));
  TrainerOptions options;
  options.threads = -2;
  auto copy = net;
  CHECK_THROWS_WITH((Trainer(sim, copy, cartpole_objective<double, 1>(), 10,
                             Adam<double>(AdamOptions<double>{1e-3}), options)),
                    Catch::Contains("threads = -2"));
}

TEST_CASE("threads: a sweep that throws while a second thread works on its steps stops both "
          "threads, and the engine sweeps correctly afterwards", "[bptt][threads]") {
  /// The cart pole, whose VJP throws once `countdown` further calls have been made (never
  /// while it is negative). Sample by sample: CartPole<double>'s batched calls would bypass
  /// the planted `vjp`, so they are hidden, and the engine takes the per-sample path.
  struct Failing : CartPole<double, 2> {
    int* countdown;
    explicit Failing(int* c) : countdown(c) {}
    void step_batch(const Matrix<double>&, const Matrix<double>&, Matrix<double>&) const = delete;
    void vjp_batch(const Matrix<double>&, const Matrix<double>&, const Matrix<double>&,
                   Matrix<double>*, Matrix<double>*) const = delete;
    void vjp(const State& x, const Control& u, const State& lambda, State* lambda_x,
             Control* lambda_u) const {
      if (*countdown >= 0 && (*countdown)-- == 0) throw std::runtime_error("planted VJP failure");
      CartPole<double, 2>::vjp(x, u, lambda, lambda_x, lambda_u);
    }
  };
  int countdown = -1;
  const Failing sim(&countdown);
  Rng rng(45);
  const Matrix<double> x0 = cartpole_initial_states(sim, rng, 6);
  const auto net = seeded_mlp<double>(sim.state_dim(), 1, 9);
  Engine alone(sim, net, cartpole_objective<double, 2>(), 25);
  const GradientPair<double> expected_pair = alone.regular_and_modified(x0, 7);
  Vector<double> expected;
  alone.forward(x0);
  alone.reverse(FlowMode::Full, expected);

  Engine engine(sim, net, cartpole_objective<double, 2>(), 25);
  engine.set_threads(2, std::numeric_limits<double>::max(), SweepThreading::Always);
  Vector<double> g;
  engine.forward(x0);
  CHECK_FALSE(engine.reverse(FlowMode::Full, g).params_overlapped);  // the loops are timed
  REQUIRE(engine.reverse(FlowMode::Full, g).params_overlapped);
  // At the first VJP, and in the middle of the sweep (6 samples a step, 2 VJPs each in the
  // pair, whose single control makes both sweeps share a backward pass and split the steps
  // between the threads).
  for (const int calls_before_failure : {0, 60}) {
    INFO("failing after " << calls_before_failure << " VJPs");
    countdown = calls_before_failure;
    CHECK_THROWS_WITH(engine.reverse(FlowMode::Full, g), "planted VJP failure");
    countdown = calls_before_failure;
    CHECK_THROWS_WITH(engine.regular_and_modified(x0, 7), "planted VJP failure");
    countdown = -1;
    engine.forward(x0);
    CHECK(engine.reverse(FlowMode::Full, g).params_overlapped);
    CHECK(g == expected);
    const GradientPair<double> pair = engine.regular_and_modified(x0, 7);
    CHECK(pair.regular_diagnostics.params_overlapped);
    CHECK(pair.regular == expected_pair.regular);
    CHECK(pair.modified == expected_pair.modified);
    CHECK(pair.modified_diagnostics.adjoint_norms == expected_pair.modified_diagnostics.adjoint_norms);
  }
}
