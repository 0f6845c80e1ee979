// The evaluation beside the next epoch's training (RunSettings::evaluate_beside,
// train/evaluation_beside.hpp): each run is made twice, with and without it, and everything
// it leaves must be bitwise the same: what run_training returns or throws, every callback's
// arguments in order, the log and the checkpoint (their seconds aside), and the trainer's
// parameters, optimizer, epoch and shuffling state. The runs without it are the truth:
// test_train_run.cpp checks them against an independent engine. Cases: every epoch
// evaluated, some, a patience stop, a requested stop, a resume of one way's checkpoint by
// the other, a non-finite evaluation (train or test set), a non-finite update in the epoch
// trained ahead, a log that cannot be written, and exceptions: from a callback (also at a
// rolled-back epoch), from the training ahead (rethrown, or dropped when the epoch before
// ends the run) and from the evaluation beside it (also while the training ahead throws).
#include <catch2/catch.hpp>

#include <sys/resource.h>

#include <atomic>
#include <csignal>
#include <filesystem>
#include <limits>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "sbptt/train/run.hpp"
#include "support/files.hpp"
#include "support/linear_trainer.hpp"

using namespace sbptt;
using sbptt::testing::file_text;
using sbptt::testing::fresh_directory;
using sbptt::testing::LinearTrainer;
using sbptt::testing::PolynomialPolicy;
using sbptt::testing::spread;
using sbptt::testing::without_seconds;
namespace fs = std::filesystem;

namespace {

/// What a training batch's backward pass does once |θ| passes `TrappedPolicy`'s radius.
enum class TrainingTrap { None, NanGradient, Throw };

/// `PolynomialPolicy` with traps that spring once |θ| passes a radius: in a training batch's
/// backward pass (a NaN parameter gradient, or an exception), and in a forward pass of more
/// than 3 samples, an evaluation's (the training batches hold 3: an exception). So a trap
/// fires at a chosen epoch, in its training or in its evaluation only. Each exception is
/// counted, in a counter its copies share, so that a test sees exceptions a run dropped.
class TrappedPolicy {
public:
  using Scalar = double;
  using Workspace = PolynomialPolicy<double>::Workspace;
  static constexpr double kNever = std::numeric_limits<double>::infinity();
  TrainingTrap training_trap = TrainingTrap::None;
  double training_radius = kNever, evaluation_radius = kNever;
  std::shared_ptr<std::atomic<int>> thrown = std::make_shared<std::atomic<int>>(0);

  explicit TrappedPolicy(std::vector<int> powers) : policy_(std::move(powers)) {}
  [[nodiscard]] Index input_dim() const { return policy_.input_dim(); }
  [[nodiscard]] Index output_dim() const { return policy_.output_dim(); }
  [[nodiscard]] Index num_params() const { return policy_.num_params(); }
  [[nodiscard]] const Vector<double>& params() const { return policy_.params(); }
  [[nodiscard]] Vector<double>& params() { return policy_.params(); }
  void forward(const Matrix<double>& x, Matrix<double>& y, Workspace& ws) const {
    if (x.cols() > 3 && beyond(evaluation_radius)) throw_counted("trapped in an evaluation");
    policy_.forward(x, y, ws);
  }
  void backward(const Workspace& ws, const Matrix<double>& dy, Vector<double>& grad,
                Matrix<double>* dx) const {
    policy_.backward(ws, dy, grad, dx);
    if (!beyond(training_radius)) return;
    if (training_trap == TrainingTrap::NanGradient)
      grad.setConstant(std::numeric_limits<double>::quiet_NaN());
    if (training_trap == TrainingTrap::Throw) throw_counted("trapped in a training batch");
  }

private:
  [[nodiscard]] bool beyond(double radius) const { return policy_.params().norm() > radius; }
  void throw_counted(const char* what) const {
    ++*thrown;
    throw std::runtime_error(what);
  }
  PolynomialPolicy<double> policy_;
};

using Setup = LinearTrainer<double, TrappedPolicy>;

fs::path scratch(const std::string& name) {
  static const fs::path dir = fresh_directory("evaluation_beside");
  return dir / name;
}

/// A record as text without its wall time.
std::string text_of(const EpochRecord& r) {
  TrainingLog one;
  EpochRecord timeless = r;
  timeless.seconds = 0;
  one.add(timeless);
  return one.csv();
}

/// The checkpoint file without the seconds of its last record (the last field of `last`).
std::string checkpoint_without_seconds(const fs::path& path) {
  std::istringstream in(file_text(path));
  std::string out;
  for (std::string line; std::getline(in, line);)
    out += (line.rfind("last ", 0) == 0 ? line.substr(0, line.rfind(' ')) : line) + "\n";
  return out;
}

/// All that one run left behind.
struct Trace {
  std::vector<std::string> calls;  ///< every callback, with its arguments, in order
  RunResult<double> result;
  Vector<double> params, adam_m, adam_v;
  long long adam_t = 0;
  long trainer_epoch = 0;
  std::string shuffle_state, log, checkpoint;
  std::string error;  ///< what the run threw
  long ahead = 0;     ///< epochs whose on_epoch saw the next epoch trained already
  int thrown = 0;     ///< exceptions of the traps, dropped or not
};

struct Case {
  Method method = Method::Combined;
  double lr = 0.02;
  NonFinitePolicy on_non_finite = NonFinitePolicy::Stop;
  Matrix<double> train = spread<double>(10, -1.0), test = spread<double>(4, 0.3);
  RunSettings settings;
  long stop_at = 0;   ///< should_stop says yes after this epoch (0: never)
  long throw_at = 0;  ///< on_epoch throws at this epoch (0: never)
  TrainingTrap training_trap = TrainingTrap::None;
  double training_radius = TrappedPolicy::kNever, evaluation_radius = TrappedPolicy::kNever;
  long log_limit = 0;  ///< bytes a file may have, as on a full disk (0: no limit)
  bool non_finite_throws = false;  ///< on_non_finite throws at an evaluation's event
};

/// Runs `c` with or without the evaluation beside, from the checkpoint `c.settings` names if
/// it exists (`keep_checkpoint`), else from scratch.
Trace run(const Case& c, bool beside, const std::string& name, bool keep_checkpoint = false) {
  Setup s(c.method, 3, c.lr, c.on_non_finite);
  s.policy.training_trap = c.training_trap;
  s.policy.training_radius = c.training_radius;
  s.policy.evaluation_radius = c.evaluation_radius;
  RunSettings settings = c.settings;
  settings.evaluate_beside = beside;
  settings.log_csv = scratch(name + ".csv").string();
  if (!settings.checkpoint.empty() && !keep_checkpoint) fs::remove(settings.checkpoint);
  Trace t;
  RunCallbacks callbacks;
  callbacks.on_resume = [&](long epoch) { t.calls.push_back("resume " + std::to_string(epoch)); };
  callbacks.on_start = [&](long epoch) { t.calls.push_back("start " + std::to_string(epoch)); };
  callbacks.on_epoch = [&](const EpochRecord& r) {
    t.calls.push_back("epoch " + text_of(r));
    if (s.trainer.epoch() > r.epoch) ++t.ahead;
    if (r.epoch == c.throw_at) throw std::runtime_error("thrown by on_epoch");
  };
  callbacks.on_non_finite = [&](const NonFiniteEvent& event, bool skipped) {
    t.calls.push_back(describe(event) + (skipped ? " skipped" : ""));
    if (c.non_finite_throws && event.phase != Phase::Update)
      throw std::runtime_error("thrown by on_non_finite");
  };
  callbacks.should_stop = [&](const EpochRecord& r) {
    t.calls.push_back("should_stop " + std::to_string(r.epoch));
    return r.epoch == c.stop_at;
  };
  rlimit unlimited{};
  REQUIRE(getrlimit(RLIMIT_FSIZE, &unlimited) == 0);
  const auto old_handler = std::signal(SIGXFSZ, SIG_IGN);
  rlimit limited = unlimited;
  if (c.log_limit > 0) limited.rlim_cur = static_cast<rlim_t>(c.log_limit);
  REQUIRE(setrlimit(RLIMIT_FSIZE, &limited) == 0);
  try {
    t.result = run_training(s.trainer, c.train, c.test, settings, callbacks);
  } catch (const std::runtime_error& e) {
    t.error = e.what();
  }
  REQUIRE(setrlimit(RLIMIT_FSIZE, &unlimited) == 0);
  std::signal(SIGXFSZ, old_handler);
  // The two ways write logs of their own names.
  std::string& message = t.result.output_error;
  if (const auto at = message.find(settings.log_csv); at != std::string::npos)
    message.replace(at, settings.log_csv.size(), "<log>");
  t.thrown = *s.policy.thrown;
  t.params = s.policy.params();
  t.adam_m = s.trainer.optimizer().first_moment();
  t.adam_v = s.trainer.optimizer().second_moment();
  t.adam_t = s.trainer.optimizer().iterations();
  t.trainer_epoch = s.trainer.epoch();
  t.shuffle_state = s.trainer.shuffle_state();
  t.log = without_seconds(file_text(settings.log_csv));
  if (!settings.checkpoint.empty() && fs::exists(settings.checkpoint))
    t.checkpoint = checkpoint_without_seconds(settings.checkpoint);
  return t;
}

void check_same(const Trace& plain, const Trace& beside) {
  CHECK(beside.calls == plain.calls);
  CHECK(beside.error == plain.error);
  CHECK(beside.result.end == plain.result.end);
  CHECK(beside.result.resumed_from == plain.result.resumed_from);
  CHECK(beside.result.epochs == plain.result.epochs);
  CHECK(beside.result.best_epoch == plain.result.best_epoch);
  CHECK(beside.result.best_loss == plain.result.best_loss);
  CHECK(beside.result.best_params == plain.result.best_params);
  CHECK(beside.result.skipped_batches == plain.result.skipped_batches);
  CHECK(beside.result.output_error == plain.result.output_error);
  CHECK(beside.result.saved_params == plain.result.saved_params);
  CHECK(beside.result.stop_event.has_value() == plain.result.stop_event.has_value());
  if (beside.result.stop_event && plain.result.stop_event)
    CHECK(describe(*beside.result.stop_event) == describe(*plain.result.stop_event));
  CHECK(beside.params == plain.params);
  CHECK(beside.adam_m == plain.adam_m);
  CHECK(beside.adam_v == plain.adam_v);
  CHECK(beside.adam_t == plain.adam_t);
  CHECK(beside.trainer_epoch == plain.trainer_epoch);
  CHECK(beside.shuffle_state == plain.shuffle_state);
  CHECK(beside.log == plain.log);
  CHECK(beside.checkpoint == plain.checkpoint);
}

/// Checks that the run with the evaluation beside matches the one without, and returns it.
Trace check_both_ways(const Case& c) {
  const Trace plain = run(c, false, "plain");
  Trace beside = run(c, true, "beside");
  check_same(plain, beside);
  CHECK(plain.ahead == 0);
  return beside;
}

}  // namespace

TEST_CASE("evaluation beside: every epoch evaluated, with checkpoints", "[train]") {
  for (Method method : {Method::Regular, Method::Combined}) {
    INFO("method " << label(method));
    Case c;
    c.method = method;
    c.settings.epochs = 9;
    c.settings.checkpoint = scratch("every.checkpoint").string();
    c.settings.checkpoint_every = 2;
    CHECK(check_both_ways(c).ahead == 8);  // all but the last
  }
}

TEST_CASE("evaluation beside: some epochs evaluated, the best restored", "[train]") {
  Case c;
  c.settings.epochs = 11;
  c.settings.evaluate_every = 3;
  c.settings.restore_best = true;
  c.settings.checkpoint = scratch("some.checkpoint").string();
  c.settings.checkpoint_every = 4;
  CHECK(check_both_ways(c).ahead == 3);  // epochs 3, 6 and 9
}

TEST_CASE("evaluation beside: a patience stop undoes the epoch trained ahead", "[train]") {
  // A large rate makes Adam overshoot the optimum, so the loss stops improving.
  Case c;
  c.method = Method::Regular;
  c.lr = 0.5;
  c.settings.epochs = 400;
  c.settings.patience = 4;
  c.settings.checkpoint = scratch("patience.checkpoint").string();
  c.settings.checkpoint_every = 0;
  const Trace plain = run(c, false, "plain");
  REQUIRE(plain.result.end == RunEnd::EarlyStop);
  REQUIRE(plain.result.epochs < 400);
  const Trace beside = run(c, true, "beside");
  check_same(plain, beside);
  CHECK(beside.ahead == plain.result.epochs);  // the last one's on_epoch too
  c.settings.restore_best = true;
  check_same(run(c, false, "plain"), run(c, true, "beside"));
}

TEST_CASE("evaluation beside: a requested stop, then a resume by the other way", "[train]") {
  Case c;
  c.settings.epochs = 12;
  c.settings.checkpoint = scratch("requested.checkpoint").string();
  c.settings.checkpoint_every = 5;
  c.stop_at = 7;
  const Trace plain = run(c, false, "plain");
  REQUIRE(plain.result.end == RunEnd::Requested);
  const Trace beside = run(c, true, "beside");
  check_same(plain, beside);
  CHECK(beside.ahead == 7);  // epoch 7's on_epoch too: 8 was trained, then undone
  // Each way's checkpoint of epoch 7 (the same text, checked above) resumed by the other.
  c.stop_at = 0;
  const Trace whole = run(c, false, "whole");
  for (bool first_beside : {false, true}) {
    INFO("stopped " << (first_beside ? "with" : "without") << " the evaluation beside");
    c.stop_at = 7;
    run(c, first_beside, "first");
    c.stop_at = 0;
    const Trace resumed = run(c, !first_beside, "first", true);
    CHECK(resumed.result.resumed_from == 7);
    CHECK(resumed.params == whole.params);
    CHECK(resumed.adam_m == whole.adam_m);
    CHECK(resumed.log == whole.log);
    CHECK(resumed.checkpoint == whole.checkpoint);
  }
}

TEST_CASE("evaluation beside: a non-finite evaluation rolls its epoch back", "[train]") {
  // One train sample overflows the rollout: its batch is skipped (SkipBatch) and the train
  // set's evaluation is not finite, which ends the run at the first evaluation, while the
  // epoch after it has already trained beside it. A test sample that overflows does the same
  // in the test set's evaluation alone.
  for (Phase phase : {Phase::TrainEvaluation, Phase::TestEvaluation}) {
    for (long evaluate_every : {1L, 2L}) {
      INFO(to_string(phase) << ", evaluate_every " << evaluate_every);
      Case c;
      c.on_non_finite = NonFinitePolicy::SkipBatch;
      (phase == Phase::TrainEvaluation ? c.train : c.test)(0, 1) = 1e300;
      c.settings.epochs = 6;
      c.settings.evaluate_every = evaluate_every;
      c.settings.checkpoint = scratch("non_finite.checkpoint").string();
      const Trace plain = run(c, false, "plain");
      REQUIRE(plain.result.end == RunEnd::NonFinite);
      REQUIRE(plain.result.stop_event->phase == phase);
      REQUIRE(plain.result.epochs == evaluate_every - 1);
      check_same(plain, run(c, true, "beside"));
    }
  }
}

namespace {

/// |θ| after each of the first 5 epochs of `c`, traps unset.
std::vector<double> norms_after_epochs(const Case& c) {
  Setup s(c.method, 3, c.lr, c.on_non_finite);
  std::vector<double> norms;
  for (int epoch = 1; epoch <= 5; ++epoch) {
    s.trainer.train_epoch(c.train, c.test, false);
    norms.push_back(s.policy.params().norm());
  }
  for (std::size_t e = 1; e < norms.size(); ++e) REQUIRE(norms[e - 1] < norms[e]);
  return norms;
}

/// Just above |θ| after `epoch`: a training trap at it springs in the next epoch's training.
double just_after_epoch(const std::vector<double>& norms, int epoch) {
  const auto e = static_cast<std::size_t>(epoch);
  return norms[e - 1] + 1e-9 * (norms[e] - norms[e - 1]);
}

/// Between |θ| after `epoch` - 1 and after `epoch`: an evaluation trap at it springs in the
/// evaluation of `epoch`.
double within_epoch(const std::vector<double>& norms, int epoch) {
  const auto e = static_cast<std::size_t>(epoch);
  return (norms[e - 2] + norms[e - 1]) / 2;
}

}  // namespace

TEST_CASE("evaluation beside: a non-finite update in the epoch trained ahead", "[train]") {
  // Epoch 3 waits for its evaluation while epoch 4, trained ahead, meets a NaN gradient:
  // epoch 3 ends as usual, then epoch 4 ends the run (Stop), rolled back.
  Case c;
  c.method = Method::Regular;
  c.settings.epochs = 8;
  c.training_trap = TrainingTrap::NanGradient;
  c.training_radius = just_after_epoch(norms_after_epochs(c), 3);
  const Trace plain = run(c, false, "plain");
  REQUIRE(plain.result.end == RunEnd::NonFinite);
  REQUIRE(plain.result.stop_event->phase == Phase::Update);
  REQUIRE(plain.result.stop_event->epoch == 4);
  const Trace beside = run(c, true, "beside");
  check_same(plain, beside);
  CHECK(beside.ahead == 3);
}

TEST_CASE("evaluation beside: a log that cannot be written", "[train]") {
  // The file-size limit makes a write past 700 bytes fail with EFBIG, like a full disk.
  Case c;
  c.settings.epochs = 40;
  c.settings.save_params = scratch("kept.txt").string();
  c.log_limit = 700;
  const Trace plain = run(c, false, "plain");
  REQUIRE(plain.result.end == RunEnd::OutputFailed);
  REQUIRE(plain.result.epochs > 1);
  const Trace beside = run(c, true, "beside");
  check_same(plain, beside);
  CHECK(beside.ahead > 0);
}

TEST_CASE("evaluation beside: a callback that throws leaves the trainer at its epoch",
          "[train]") {
  Case c;
  c.settings.epochs = 8;
  c.throw_at = 3;
  const Trace plain = run(c, false, "plain");
  REQUIRE(plain.error == "thrown by on_epoch");
  REQUIRE(plain.trainer_epoch == 3);
  const Trace beside = run(c, true, "beside");
  check_same(plain, beside);
  CHECK(beside.ahead == 3);
}

TEST_CASE("evaluation beside: a callback that throws at a non-finite evaluation", "[train]") {
  // Epoch 1's evaluation of the test set is not finite, so epoch 1 is rolled back, and the
  // callback told of it throws: the trainer holds the parameters from before epoch 1.
  Case c;
  c.test(0, 1) = 1e300;
  c.settings.epochs = 5;
  c.non_finite_throws = true;
  const Trace plain = run(c, false, "plain");
  REQUIRE(plain.error == "thrown by on_non_finite");
  REQUIRE(plain.params == Vector<double>::Zero(2));
  check_same(plain, run(c, true, "beside"));
}

TEST_CASE("evaluation beside: an exception of the training ahead waits for the epoch before",
          "[train]") {
  // Epoch 4, trained ahead, throws: the run rethrows it once epoch 3 has ended, as a run
  // without the look-ahead would, unless epoch 3 ends the run, which then never trains 4.
  for (long stop_at : {0L, 3L}) {
    INFO("stop at " << stop_at);
    Case c;
    c.settings.epochs = 8;
    c.settings.checkpoint = scratch("thrown.checkpoint").string();
    c.training_trap = TrainingTrap::Throw;
    c.training_radius = just_after_epoch(norms_after_epochs(c), 3);
    c.stop_at = stop_at;
    const Trace plain = run(c, false, "plain");
    REQUIRE(plain.error == (stop_at == 0 ? "trapped in a training batch" : ""));
    REQUIRE(plain.result.epochs == stop_at);  // nothing is returned when it throws
    REQUIRE(plain.trainer_epoch == (stop_at == 0 ? 4 : 3));
    const Trace beside = run(c, true, "beside");
    check_same(plain, beside);
    CHECK(beside.thrown == 1);  // with the stop at 3, thrown and dropped
    CHECK(beside.ahead == 3);
  }
}

TEST_CASE("evaluation beside: an exception of the training ahead is dropped when the epoch "
          "before ends the run", "[train]") {
  // Epoch 4 is the first evaluated one, and its test set's evaluation is not finite, which
  // ends the run at epoch 3's parameters. Epoch 5, trained ahead, throws: without the
  // look-ahead it never trained.
  Case c;
  c.settings.epochs = 8;
  c.settings.evaluate_every = 4;
  c.training_trap = TrainingTrap::Throw;
  c.training_radius = just_after_epoch(norms_after_epochs(c), 4);
  c.test(0, 1) = 1e300;
  const Trace plain = run(c, false, "plain");
  REQUIRE(plain.error.empty());
  REQUIRE(plain.result.end == RunEnd::NonFinite);
  REQUIRE(plain.result.stop_event->epoch == 4);
  REQUIRE(plain.thrown == 0);
  const Trace beside = run(c, true, "beside");
  check_same(plain, beside);
  CHECK(beside.thrown == 1);
}

TEST_CASE("evaluation beside: an exception of the evaluation leaves the trainer at its epoch",
          "[train]") {
  // Epoch 4's evaluation throws; in the run with the look-ahead epoch 5's training throws too,
  // and the evaluation's exception is the one that comes out, as without it.
  for (bool training_throws_too : {false, true}) {
    INFO("training throws too: " << training_throws_too);
    Case c;
    c.settings.epochs = 8;
    const std::vector<double> norms = norms_after_epochs(c);
    c.evaluation_radius = within_epoch(norms, 4);
    if (training_throws_too) {
      c.training_trap = TrainingTrap::Throw;
      c.training_radius = just_after_epoch(norms, 4);
    }
    const Trace plain = run(c, false, "plain");
    REQUIRE(plain.error == "trapped in an evaluation");
    REQUIRE(plain.trainer_epoch == 4);
    REQUIRE(plain.thrown == 1);
    const Trace beside = run(c, true, "beside");
    check_same(plain, beside);
    CHECK(beside.thrown == (training_throws_too ? 2 : 1));
  }
}

namespace {

/// A controller that is a view of a policy: its copies are views of the same parameters.
struct PolicyView {
  using Scalar = double;
  using Workspace = PolynomialPolicy<double>::Workspace;
  PolynomialPolicy<double>* policy;

  [[nodiscard]] Index input_dim() const { return policy->input_dim(); }
  [[nodiscard]] Index output_dim() const { return policy->output_dim(); }
  [[nodiscard]] Index num_params() const { return policy->num_params(); }
  [[nodiscard]] const Vector<double>& params() const { return policy->params(); }
  [[nodiscard]] Vector<double>& params() { return policy->params(); }
  void forward(const Matrix<double>& x, Matrix<double>& y, Workspace& ws) const {
    policy->forward(x, y, ws);
  }
  void backward(const Workspace& ws, const Matrix<double>& dy, Vector<double>& grad,
                Matrix<double>* dx) const {
    policy->backward(ws, dy, grad, dx);
  }
};

}  // namespace

TEST_CASE("evaluation beside: a controller whose copy is a view is refused before any work",
          "[train]") {
  LinearTrainer<double> s(Method::Regular);
  PolicyView view{&s.policy};
  Trainer trainer(s.sim, view, sbptt::testing::to_origin<double>(), 6,
                  Adam<double>(AdamOptions<double>{0.02}),
                  LinearTrainer<double>::options(Method::Regular, 3, NonFinitePolicy::Stop));
  const Vector<double> before = s.policy.params();
  RunSettings settings;
  settings.epochs = 3;
  settings.evaluate_beside = true;
  const Matrix<double> train = spread<double>(6, -1.0), test = spread<double>(2, 0.3);
  CHECK_THROWS_WITH(run_training(trainer, train, test, settings),
                    Catch::Contains("evaluate_beside: the copy of the controller shares its "
                                    "parameters with the trained one"));
  CHECK(s.policy.params() == before);
  CHECK(trainer.epoch() == 0);
  settings.evaluate_beside = false;
  CHECK(run_training(trainer, train, test, settings).epochs == 3);
}
