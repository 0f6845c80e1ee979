// The trainer on the linear system x' = a x + b c with c = θ x (the LQR-type question of the
// ICLR review): every method must drive θ to the closed-form optimum, and the bookkeeping of
// the training log and the non-finite policy must hold. And the threads' options reach the
// engine, on the cart pole with a network (whose sweeps meet the other thread at every step).
#include <catch2/catch.hpp>

#include <cmath>
#include <limits>
#include <memory>
#include <string>
#include <utility>

#include "sbptt/bptt/losses.hpp"
#include "sbptt/bptt/sweep_threading.hpp"
#include "sbptt/nn/init.hpp"
#include "sbptt/nn/network.hpp"
#include "sbptt/objectives/cartpole.hpp"
#include "sbptt/optim/adam.hpp"
#include "sbptt/optim/sgd.hpp"
#include "sbptt/sim/cartpole.hpp"
#include "sbptt/sim/linear.hpp"
#include "sbptt/train/trainer.hpp"
#include "polynomial_policy.hpp"

using namespace sbptt;
using sbptt::testing::PolynomialPolicy;

namespace {

using Sim = LinearSystem<double, 1, 1>;
using Loss = SquaredDistanceLoss<Sim::State>;
using Policy = PolynomialPolicy<double>;

Objective<Loss> to_origin(LossTiming timing) {
  return {Loss{Sim::State::Zero()}, timing, 1.0, 0.0};
}

Matrix<double> samples(std::initializer_list<double> values) {
  Matrix<double> m(1, static_cast<Index>(values.size()));
  Index i = 0;
  for (double v : values) m(0, i++) = v;
  return m;
}

/// x' = 3x + c: from 1e306 a state overflows within the 10 steps, from 1 it does not.
const Sim unstable = Sim::scalar(3.0, 1.0);

/// R updates of one sample per batch on `unstable`, Adam at lr 0.01, a final loss.
Trainer<Sim, Policy, Loss, Adam<double>> unstable_trainer(Policy& policy,
                                                         NonFinitePolicy on_non_finite) {
  TrainerOptions options;
  options.method = Method::Regular;
  options.batch = 1;
  options.on_non_finite = on_non_finite;
  return {unstable, policy, to_origin(LossTiming::Final), 10,
          Adam<double>(AdamOptions<double>{0.01}), options};
}

}  // namespace

TEST_CASE("trainer: R, M and C all converge to the dead-beat optimum θ* = −a/b", "[train]") {
  // With a final loss ½ x_m², L = ½ ρ^{2m} x_0², minimised exactly at ρ = a + bθ = 0.
  const double a = 1.1, b = 0.8;
  const Sim sim = Sim::scalar(a, b);
  const Matrix<double> train = samples({0.5, -1.0, 1.5, 2.0});
  for (Method method : {Method::Regular, Method::Modified, Method::Combined}) {
    Policy policy({1});
    TrainerOptions options;
    options.method = method;
    options.batch = 2;
    // Plain gradient descent: its steps shrink with the vector, so it settles on a fixed point
    // of the update field, which is what this test asks about.
    Trainer trainer(sim, policy, to_origin(LossTiming::Continuous), 4,
                    Sgd<double>(SgdOptions<double>{0.05}), options);
    EpochRecord last;
    for (int epoch = 0; epoch < 300; ++epoch) last = trainer.train_epoch(train, train);
    INFO("method " << label(method) << ", theta " << policy.params()(0));
    CHECK(policy.params()(0) == Approx(-a / b).epsilon(1e-9));
    CHECK(last.train_loss.value() < 1e-15);
  }
}

TEST_CASE("trainer: the log fields follow their definitions", "[train]") {
  const Sim sim = Sim::scalar(0.9, 0.5);
  const Matrix<double> train = samples({0.5, -1.0, 1.5}), test = samples({2.0});
  Policy policy({1});
  policy.params()(0) = 0.3;
  TrainerOptions options;
  options.method = Method::Regular;
  options.batch = 2;  // batches {0.5, -1.0} and {1.5}
  Trainer trainer(sim, policy, to_origin(LossTiming::Final), 3,
                  Adam<double>(AdamOptions<double>{0.01}), options);

  // Expected batch losses and gradients with the parameters before each update.
  Policy probe({1});
  probe.params() = policy.params();
  Engine engine(sim, probe, to_origin(LossTiming::Final), 3);
  Adam<double> adam(AdamOptions<double>{0.01});
  Vector<double> g;
  double losses = 0, norms = 0;
  for (const auto& batch : {samples({0.5, -1.0}), samples({1.5})}) {
    losses += engine.forward(batch);
    engine.reverse(FlowMode::Full, g);
    norms += g.squaredNorm();
    adam.step(probe.params(), g);
  }
  const EpochRecord record = trainer.train_epoch(train, test);
  CHECK(record.epoch == 1);
  CHECK(policy.params()(0) == probe.params()(0));
  CHECK(record.batch_loss == Approx(losses / 2));
  CHECK(record.update_norm2 == Approx(norms / 2));
  CHECK(record.train_loss.value() == Approx(engine.evaluate(train)));
  CHECK(record.test_loss.value() == Approx(engine.evaluate(test)));
  CHECK_FALSE(record.cos_m_r);
  CHECK(record.seconds >= 0);

  TrainingLog log;
  log.add(record);
  const std::string csv = log.csv();
  CHECK(csv.rfind(TrainingLog::header, 0) == 0);
  CHECK(csv.find("\n1,") != std::string::npos);
}

TEST_CASE("trainer: a non-finite update leaves the last finite parameters", "[train]") {
  const Matrix<double> train = samples({1e306, 1.0});
  for (auto policy_kind : {NonFinitePolicy::Stop, NonFinitePolicy::SkipBatch}) {
    Policy policy({1});
    policy.params()(0) = 0.01;
    auto trainer = unstable_trainer(policy, policy_kind);
    trainer.train_epoch(train, train);
    REQUIRE_FALSE(trainer.non_finite_events().empty());
    CHECK(trainer.non_finite_events().front().batch == 0);
    CHECK(trainer.non_finite_events().front().where.quantity == Quantity::State);
    // Stop ends the epoch at batch 0; SkipBatch steps on batch 1, but the set still overflows
    // in both evaluations, so it stops too. Both keep θ as the epoch found it.
    CHECK(trainer.stopped());
    CHECK(trainer.non_finite_events().size() ==
          (policy_kind == NonFinitePolicy::Stop ? 1u : 3u));
    CHECK(policy.params()(0) == 0.01);
  }
}

TEST_CASE("trainer: parse_method accepts short and long names and rejects others", "[train]") {
  CHECK(parse_method("C") == Method::Combined);
  CHECK(parse_method("modified") == Method::Modified);
  CHECK(parse_method("Regular") == Method::Regular);
  CHECK(parse_method("s") == Method::Stopped);
  CHECK(parse_method("network") == Method::NetworkOnly);
  REQUIRE_THROWS_WITH(parse_method("Q"), Catch::Contains("'Q'") && Catch::Contains("R, M, C, S, N"));
}

namespace {

/// Fault injection: c = θ1 x + θ2, but the input product reports an infinite feedback, so the
/// regular sweep (which uses it) overflows while the modified one (which does not) stays finite.
struct InfiniteFeedbackPolicy : Policy {
  InfiniteFeedbackPolicy() : Policy({1, 0}) {}
  void backward(const Workspace& ws, const Matrix<double>& dy, Vector<double>& grad,
                Matrix<double>* dx) const {
    Policy::backward(ws, dy, grad, dx);
    if (dx) *dx = dy * std::numeric_limits<double>::infinity();
  }
};

}  // namespace

TEST_CASE("trainer: C stays finite when g_R overflows; R stops and keeps its parameters",
          "[train]") {
  const Sim sim = Sim::scalar(0.9, 0.5);
  const Matrix<double> train = samples({0.5, -1.0, 1.5, 2.0});
  for (Method method : {Method::Combined, Method::Regular}) {
    InfiniteFeedbackPolicy policy;
    policy.params() << 0.2, 0.1;
    const Vector<double> start = policy.params();
    TrainerOptions options;
    options.method = method;
    options.batch = 2;
    Trainer trainer(sim, policy, to_origin(LossTiming::Continuous), 5,
                    Adam<double>(AdamOptions<double>{0.01}), options);
    const EpochRecord record = trainer.train_epoch(train, train);
    INFO("method " << label(method));
    CHECK(policy.params().allFinite());
    if (method == Method::Combined) {
      CHECK_FALSE(trainer.last_non_finite());
      CHECK(policy.params() != start);  // it did step, with g_R's NaN components dropped
      CHECK(std::isfinite(record.update_norm2));
    } else {
      REQUIRE(trainer.last_non_finite());
      CHECK(trainer.last_non_finite()->where.quantity == Quantity::Adjoint);
      // λ_5 is the finite loss seed; λ_4 is the first adjoint the infinite K_4 feeds, and the
      // first sample of the first batch (x_0 = 0.5) already has a non-zero μ.
      CHECK(trainer.last_non_finite()->where.step == 4);
      CHECK(trainer.last_non_finite()->where.sample == 0);
      CHECK(policy.params() == start);
    }
  }
}

TEST_CASE("trainer: a loss that overflows from finite states is reported as the loss",
          "[train]") {
  // x' = x with c = 0: the states stay at their start, but ½ x² of 1e200 overflows.
  const Sim sim = Sim::scalar(1.0, 1.0);
  Policy policy({1});
  TrainerOptions options;
  options.method = Method::Regular;
  options.batch = 2;
  Trainer trainer(sim, policy, to_origin(LossTiming::Final), 3,
                  Adam<double>(AdamOptions<double>{0.01}), options);
  trainer.train_epoch(samples({1.0, 1e200}), samples({1.0}));
  REQUIRE(trainer.last_non_finite());
  const NonFiniteEvent& event = *trainer.last_non_finite();
  CHECK(event.where.quantity == Quantity::Loss);
  CHECK(event.where.step == 3);
  CHECK(event.where.sample == 1);
  CHECK(event.where.value == std::numeric_limits<double>::infinity());
  CHECK(event.phase == Phase::Update);
  CHECK(trainer.stopped());
  CHECK(policy.params()(0) == 0.0);
}

TEST_CASE("trainer: a running loss that overflows is reported at the step it overflowed",
          "[train]") {
  // x' = 2x with c = 0 from 1e300: every state is finite, but ½ x_1² overflows at step 1 of 6.
  // Every loss event was reported at the last step, where the sum ends.
  const Sim doubling = Sim::scalar(2.0, 1.0);
  const Matrix<double> finite = samples({1.0, 0.5}), overflowing = samples({1.0, 1e300});
  for (const auto timing : {LossTiming::Continuous, LossTiming::Final}) {
    const Index expected_step = timing == LossTiming::Continuous ? 1 : 6;
    INFO("continuous " << (timing == LossTiming::Continuous));
    for (const bool in_update : {true, false}) {
      Policy policy({1});
      TrainerOptions options;
      options.method = Method::Regular;
      options.batch = 2;
      Trainer trainer(doubling, policy, to_origin(timing), 6,
                      Adam<double>(AdamOptions<double>{0.01}), options);
      trainer.train_epoch(in_update ? overflowing : finite, in_update ? finite : overflowing);
      INFO("in an update " << in_update);
      REQUIRE(trainer.last_non_finite());
      const NonFiniteEvent& event = *trainer.last_non_finite();
      CHECK(event.phase == (in_update ? Phase::Update : Phase::TestEvaluation));
      CHECK(event.where.quantity == Quantity::Loss);
      CHECK(event.where.step == expected_step);
      CHECK(event.where.sample == 1);
    }
  }
}

namespace {

/// Fault injection: the parameter gradient of θ2 is NaN while states and adjoints stay finite.
struct NanGradientPolicy : Policy {
  NanGradientPolicy() : Policy({1, 0}) {}
  void backward(const Workspace& ws, const Matrix<double>& dy, Vector<double>& grad,
                Matrix<double>* dx) const {
    Policy::backward(ws, dy, grad, dx);
    grad(1) = std::numeric_limits<double>::quiet_NaN();
  }
};

/// Adam whose `fail_at`-th step (counted in a counter the trainer's backup cannot rewind)
/// leaves θ1 infinite after taking its step, as an overflowing update would.
struct OverflowingAdam : Adam<double> {
  OverflowingAdam(int* calls, int fail_at)
      : Adam<double>(AdamOptions<double>{0.01}), calls_(calls), fail_at_(fail_at) {}
  void step(Vector<double>& params, const Vector<double>& grad) {
    Adam<double>::step(params, grad);
    if (++*calls_ == fail_at_) params(0) = std::numeric_limits<double>::infinity();
  }
  int* calls_;
  int fail_at_;
};

}  // namespace

TEST_CASE("trainer: a non-finite parameter gradient is reported as the gradient", "[train]") {
  const Sim sim = Sim::scalar(0.9, 0.5);
  NanGradientPolicy policy;
  policy.params() << 0.2, 0.1;
  const Vector<double> start = policy.params();
  TrainerOptions options;
  options.method = Method::Modified;
  options.batch = 2;
  Trainer trainer(sim, policy, to_origin(LossTiming::Continuous), 5,
                  Adam<double>(AdamOptions<double>{0.01}), options);
  trainer.train_epoch(samples({0.5, -1.0}), samples({1.0}));
  REQUIRE(trainer.last_non_finite());
  const NonFinite& where = trainer.last_non_finite()->where;
  CHECK(where.quantity == Quantity::Gradient);
  CHECK(where.sample == 1);  // the parameter index
  CHECK(std::isnan(where.value));
  CHECK(policy.params() == start);
}

TEST_CASE("trainer: a skipped batch leaves no trace in the parameters or in Adam's m, v, t",
          "[train]") {
  // The second of three steps overflows θ after Adam has updated its moments; skipping it
  // must give exactly the run that never saw that batch.
  const Sim sim = Sim::scalar(0.9, 0.5);
  int calls = 0, unused = 0;
  Policy skipping({1}), reference({1});
  skipping.params()(0) = reference.params()(0) = 0.3;
  TrainerOptions options;
  options.method = Method::Regular;
  options.batch = 1;
  options.on_non_finite = NonFinitePolicy::SkipBatch;
  Trainer with_skip(sim, skipping, to_origin(LossTiming::Final), 3, OverflowingAdam(&calls, 2),
                    options);
  Trainer without(sim, reference, to_origin(LossTiming::Final), 3, OverflowingAdam(&unused, 0),
                  options);
  const EpochRecord record = with_skip.train_epoch(samples({0.5, -1.0, 1.5}), samples({1.0}));
  without.train_epoch(samples({0.5, 1.5}), samples({1.0}));
  REQUIRE(with_skip.last_non_finite());
  // The gradient was finite: the step made the parameter infinite, and the report says so.
  CHECK(with_skip.last_non_finite()->where.quantity == Quantity::Parameter);
  CHECK(describe(*with_skip.last_non_finite()) ==
        "non-finite parameter (inf) in epoch 1, batch 1, parameter 0");
  CHECK(with_skip.last_non_finite()->where.sample == 0);
  CHECK(with_skip.last_non_finite()->batch == 1);
  CHECK_FALSE(with_skip.stopped());
  CHECK(with_skip.non_finite_events().size() == 1);
  CHECK(with_skip.optimizer().iterations() == 2);
  CHECK(skipping.params()(0) == reference.params()(0));
  CHECK(std::isfinite(record.test_loss.value()));
}

TEST_CASE("trainer: an event's NaN reads nan whatever its sign bit", "[train]") {
  // 0 * inf and inf - inf give a NaN with the sign bit set on x86, which the stream writes
  // as "-nan": a sign that means nothing (the chain runs of docs/results showed it).
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  NonFiniteEvent event;
  event.epoch = 2;
  event.batch = 1;
  event.where = {Quantity::State, 9, 0, -nan};
  CHECK(describe(event) == "non-finite state (nan) in epoch 2, batch 1, step 9, sample 0");
  event.where.value = nan;
  CHECK(describe(event) == "non-finite state (nan) in epoch 2, batch 1, step 9, sample 0");
  event.where.value = -inf;
  CHECK(describe(event) == "non-finite state (-inf) in epoch 2, batch 1, step 9, sample 0");
}

TEST_CASE("trainer: a non-finite value in an update names the train set's column, shuffled or not",
          "[train]") {
  // The loss of the sample at column 4 (1e200) overflows. Before, an update reported the
  // sample's place in its mini-batch (0 or 1 here), which after a shuffle names no column a
  // user can find; an evaluation reports the set's column, and so does an update now.
  const Sim sim = Sim::scalar(1.0, 1.0);
  for (const bool shuffle : {false, true}) {
    Policy policy({1});
    TrainerOptions options;
    options.method = Method::Regular;
    options.batch = 2;
    options.shuffle = shuffle;
    Trainer trainer(sim, policy, to_origin(LossTiming::Final), 3,
                    Adam<double>(AdamOptions<double>{0.01}), options);
    trainer.train_epoch(samples({1.0, 0.5, -0.5, 0.25, 1e200, 2.0}), samples({1.0}));
    INFO("shuffle " << shuffle);
    REQUIRE(trainer.last_non_finite());
    const NonFiniteEvent& event = *trainer.last_non_finite();
    CHECK(event.phase == Phase::Update);
    CHECK(event.where.quantity == Quantity::Loss);
    CHECK(event.where.sample == 4);
    if (!shuffle) CHECK(event.batch == 2);
  }
}

TEST_CASE("trainer: a non-finite evaluation stops training and rolls the epoch back",
          "[train]") {
  // The test set overflows from 1e306 in its evaluation; the training batches stay finite.
  for (auto policy_kind : {NonFinitePolicy::Stop, NonFinitePolicy::SkipBatch}) {
    Policy policy({1});
    policy.params()(0) = 0.01;
    auto trainer = unstable_trainer(policy, policy_kind);
    trainer.train_epoch(samples({1.0, 0.5}), samples({2.0, 1e306}));
    REQUIRE(trainer.last_non_finite());
    const NonFiniteEvent& event = *trainer.last_non_finite();
    CHECK(event.phase == Phase::TestEvaluation);
    CHECK(event.where.quantity == Quantity::State);
    CHECK(event.where.sample == 1);
    CHECK(trainer.stopped());
    // Back to the parameters and optimizer state before the epoch: the last ones evaluated.
    CHECK(policy.params()(0) == 0.01);
    CHECK(trainer.optimizer().iterations() == 0);
  }
}

namespace {

/// What `Refusing` refused: how many steps, and the first state it refused to step from.
struct Refusals {
  long count = 0;
  double first_x = 0;
};

std::string describe(const Refusals& r) {
  return r.count == 0 ? std::string()
                      : detail::concat("refused ", r.count, " steps, the first from x = ",
                                       detail::shortest(r.first_x));
}

/// `unstable`, refusing (with NaN) to step from |x| > 1e300, as MuJoCo refuses values beyond
/// its bound, and keeping a record of it as `MujocoSimulator` does.
struct Refusing {
  using Scalar = double;
  using State = Sim::State;
  using Control = Sim::Control;
  std::shared_ptr<Refusals> record = std::make_shared<Refusals>();

  [[nodiscard]] Index state_dim() const { return 1; }
  [[nodiscard]] Index control_dim() const { return 1; }
  void step(const State& x, const Control& u, State& x_next) const {
    if (std::abs(x(0)) > 1e300) {
      if (record->count++ == 0) record->first_x = x(0);
      x_next.setConstant(std::numeric_limits<double>::quiet_NaN());
      return;
    }
    unstable.step(x, u, x_next);
  }
  void vjp(const State& x, const Control& u, const State& lambda, State* lambda_x,
           Control* lambda_u) const {
    unstable.vjp(x, u, lambda, lambda_x, lambda_u);
  }
  [[nodiscard]] Refusals take_refusals() const { return std::exchange(*record, Refusals{}); }
};
static_assert(ExplainsRefusals<Refusing>);
static_assert(!ExplainsRefusals<Sim>);

}  // namespace

TEST_CASE("trainer: a simulator's account of its refusals goes with the non-finite event",
          "[train]") {
  // From 1e300 the first step gives 3e300, which the second refuses, in the update or in the
  // test set's evaluation.
  const Refusing sim;
  TrainerOptions options;
  options.method = Method::Regular;
  options.batch = 1;
  for (const Phase phase : {Phase::Update, Phase::TestEvaluation}) {
    Policy policy({1});
    policy.params()(0) = 0.01;
    Trainer trainer(sim, policy, to_origin(LossTiming::Final), 10,
                    Adam<double>(AdamOptions<double>{0.01}), options);
    const Matrix<double> overflowing = samples({1.0, 1e300}), finite = samples({0.5});
    // A refusal the caller met before the epoch is not the cause of the epoch's event.
    Sim::State refused;
    sim.step(Sim::State::Constant(2e300), Sim::Control::Zero(), refused);
    if (phase == Phase::Update) {
      trainer.train_epoch(overflowing, finite);
    } else {
      trainer.train_epoch(finite, overflowing);
    }
    REQUIRE(trainer.last_non_finite());
    const NonFiniteEvent& event = *trainer.last_non_finite();
    CHECK(event.phase == phase);
    CHECK(event.where.step == 2);
    CHECK(event.cause == "refused 1 steps, the first from x = 3e+300");
    CHECK_THAT(describe(event),
               Catch::EndsWith(", step 2, sample 1; refused 1 steps, the first from x = 3e+300"));
    CHECK(sim.record->count == 0);  // taken
  }
  // A simulator without an account: no cause, and the words end with the place.
  Policy policy({1});
  policy.params()(0) = 0.01;
  auto trainer = unstable_trainer(policy, NonFinitePolicy::Stop);
  trainer.train_epoch(samples({1e306}), samples({0.5}));
  REQUIRE(trainer.last_non_finite());
  CHECK(trainer.last_non_finite()->cause.empty());
  CHECK_THAT(describe(*trainer.last_non_finite()), Catch::EndsWith("sample 0"));
}

TEST_CASE("trainer: Stop mid-epoch returns to the parameters the last epoch evaluated",
          "[train]") {
  Policy policy({1});
  policy.params()(0) = 0.01;
  auto trainer = unstable_trainer(policy, NonFinitePolicy::Stop);
  trainer.train_epoch(samples({1.0, 1e306}), samples({1.0}));
  REQUIRE(trainer.stopped());
  CHECK(trainer.last_non_finite()->batch == 1);
  CHECK(policy.params()(0) == 0.01);  // batch 0's step is undone: it was never evaluated
  CHECK(trainer.optimizer().iterations() == 0);
}

TEST_CASE("trainer: skip-batch stops when no batch of an epoch was finite", "[train]") {
  Policy policy({1});
  auto trainer = unstable_trainer(policy, NonFinitePolicy::SkipBatch);
  trainer.train_epoch(samples({1e306, -1e306}), samples({1.0}));
  CHECK(trainer.non_finite_events().size() == 2);
  CHECK(trainer.stopped());
}

TEST_CASE("trainer: the sweep_threading option sets its engine's way", "[train]") {
  const CartPole<double, 2> sim;
  auto initial = Network<double>::mlp(sim.state_dim(), {16}, 1);
  Rng rng(7);
  glorot_uniform(initial, rng);
  const Matrix<double> train = cartpole_initial_states(sim, rng, 56);
  const Matrix<double> test = cartpole_initial_states(sim, rng, 8);
  // 7 batches of 8, each one lone sweep's (R: the cart pole is a BatchSimulator, so with the
  // default split every sweep hands its parameter products to the second thread) or one
  // shared-seed pair's (C: one control). Timed: the first batch at this size on the threads,
  // untimed, then a probing of 3 on the threads and 3 alone.
  struct Expected {
    SweepThreading way;
    Index threaded, alone;
  };
  for (const Method method : {Method::Regular, Method::Combined}) {
    for (const Expected expected : {Expected{SweepThreading::Always, 7, 0},
                                    Expected{SweepThreading::Never, 0, 7},
                                    Expected{SweepThreading::Timed, 4, 3}}) {
      INFO(label(method) << ", " << to_string(expected.way));
      auto net = initial;
      TrainerOptions options;
      options.method = method;
      options.threads = 2;
      options.sweep_threading = expected.way;
      Trainer trainer(sim, net, cartpole_objective<double, 2>(), 20,
                      Adam<double>(AdamOptions<double>{1e-3}), options);
      trainer.train_epoch(train, test);
      const SweepTally tally = trainer.engine().sweep_tally();
      CHECK(tally.threaded == expected.threaded);
      CHECK(tally.alone == expected.alone);
    }
  }
}
