// The training driver (train/run.hpp) on the linear system x' = a x + b c with c = θ x: its
// log equals the rows the trainer returned, its evaluations equal an independent engine's,
// the best parameters give the best loss, the patience stop, checkpoints resume bit for bit,
// and failed outputs keep the parameters.
#include <catch2/catch.hpp>

#include <sys/resource.h>

#include <algorithm>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <limits>
#include <optional>
#include <sstream>
#include <string>
#include <vector>
#include <unistd.h>

#include "sbptt/train/run.hpp"
#include "polynomial_policy.hpp"
#include "support/files.hpp"
#include "support/linear_trainer.hpp"

using namespace sbptt;
using sbptt::testing::PolynomialPolicy;
using sbptt::testing::spread;
using sbptt::testing::to_origin;
using sbptt::testing::file_text;
using sbptt::testing::fresh_directory;
using sbptt::testing::without_seconds;
namespace fs = std::filesystem;

namespace {

template <class Scalar>
using Setup = sbptt::testing::LinearTrainer<Scalar>;

/// `name` in a directory of this process, emptied once at the first call.
fs::path scratch(const std::string& name) {
  static const fs::path dir = fresh_directory("run");
  return dir / name;
}

/// A resource limit of this process, set back to what it was when this object ends: a test that
/// lowers it and then fails must not leave it lowered for the tests after it.
struct RestoredLimit {
  using Resource = decltype(RLIMIT_NOFILE);  // an enum in glibc's C++ declarations
  explicit RestoredLimit(Resource which) : resource(which) {
    REQUIRE(getrlimit(resource, &old) == 0);
  }
  RestoredLimit(const RestoredLimit&) = delete;
  RestoredLimit& operator=(const RestoredLimit&) = delete;
  ~RestoredLimit() { setrlimit(resource, &old); }
  Resource resource;
  rlimit old{};
};

/// Settings of a run of `epochs` epochs with the checkpoint `name` in the scratch directory,
/// none there yet.
RunSettings fresh_checkpoint_run(const std::string& name, long epochs) {
  fs::remove(scratch(name));
  RunSettings settings;
  settings.epochs = epochs;
  settings.checkpoint = scratch(name).string();
  return settings;
}

}  // namespace

TEST_CASE("run: the log holds exactly the returned rows, evaluated on schedule", "[train]") {
  Setup<double> s(Method::Combined);
  const Matrix<double> train = spread<double>(10, -1.0), test = spread<double>(4, 0.3);
  RunSettings settings;
  settings.epochs = 10;
  settings.evaluate_every = 3;
  settings.log_csv = scratch("schedule.csv").string();
  TrainingLog expected;
  PolynomialPolicy<double> probe({2, 1});
  Engine engine(s.sim, probe, to_origin<double>(), 6);
  RunCallbacks callbacks;
  callbacks.on_epoch = [&](const EpochRecord& r) {
    expected.add(r);
    const bool scheduled = r.epoch % 3 == 0 || r.epoch == 10;
    CHECK(r.train_loss.has_value() == scheduled);
    CHECK(r.test_loss.has_value() == scheduled);
    if (scheduled) {  // an independent evaluation of the parameters after the epoch
      probe.params() = s.policy.params();
      CHECK(*r.train_loss == engine.evaluate(train));
      CHECK(*r.test_loss == engine.evaluate(test));
    }
  };
  const auto result = run_training(s.trainer, train, test, settings, callbacks);
  CHECK(result.end == RunEnd::Finished);
  CHECK(result.epochs == 10);
  CHECK(expected.rows().size() == 10);
  CHECK(file_text(settings.log_csv) == expected.csv());
}

TEST_CASE("run: the log file grows by one write per epoch, each byte written once", "[train]") {
  const std::string path = scratch("linear.csv").string();
  TrainingLogFile log = TrainingLogFile::create(path);
  EpochRecord r;
  for (long e = 1; e <= 500; ++e) {
    r.epoch = e;
    r.train_loss = 1.0 / double(e);
    log.append(r);
  }
  CHECK(log.writes() == 501);  // the header, then one per row
  CHECK(log.bytes_written() == static_cast<long long>(fs::file_size(path)));
  CHECK(log.size() == static_cast<long long>(fs::file_size(path)));
}

TEST_CASE("run: a log removed during the run is put back; one replaced ends the run",
          "[train]") {
  // Removed (or renamed away), the log went on growing unlinked and was lost at the end, the
  // run ending as a success; its checkpoint, which names the log, could not be resumed.
  const Matrix<double> train = spread<double>(6, -1.0), test = spread<double>(2, 0.2);
  const fs::path removed = scratch("removed.csv"), moved = scratch("moved.csv");
  for (const bool rename_away : {false, true}) {
    INFO("renamed away " << rename_away);
    Setup<double> s(Method::Regular, 3);
    RunSettings settings = fresh_checkpoint_run("removed.checkpoint", 6);
    settings.log_csv = removed.string();
    TrainingLog rows;
    RunCallbacks callbacks;
    callbacks.on_epoch = [&](const EpochRecord& r) {
      rows.add(r);
      if (r.epoch != 2) return;
      if (rename_away)
        fs::rename(removed, moved);
      else
        fs::remove(removed);
    };
    const auto result = run_training(s.trainer, train, test, settings, callbacks);
    CHECK(result.end == RunEnd::Finished);
    CHECK(file_text(removed) == rows.csv());
    // The checkpoint continues it: a rerun of more epochs resumes.
    Setup<double> again(Method::Regular, 3);
    settings.epochs = 8;
    const auto resumed = run_training(again.trainer, train, test, settings);
    CHECK(resumed.resumed_from == 6);
    CHECK(resumed.end == RunEnd::Finished);
  }

  // Another file in its place is another writer's: the run ends, the parameters saved, and
  // that file is left as it is.
  const fs::path params = scratch("replaced.txt");
  Setup<double> s(Method::Regular, 3);
  RunSettings settings;
  settings.epochs = 6;
  settings.log_csv = scratch("replaced.csv").string();
  settings.save_params = params.string();
  RunCallbacks callbacks;
  callbacks.on_epoch = [&](const EpochRecord& r) {
    if (r.epoch != 2) return;
    fs::remove(settings.log_csv);
    std::ofstream(settings.log_csv) << "another file\n";
  };
  const auto result = run_training(s.trainer, train, test, settings, callbacks);
  CHECK(result.end == RunEnd::OutputFailed);
  CHECK(result.epochs == 3);  // its row was the write refused
  CHECK_THAT(result.output_error, Catch::Contains("training log '" + settings.log_csv +
                                                  "' was replaced by another file during the run"));
  CHECK(file_text(settings.log_csv) == "another file\n");
  CHECK(result.saved_params == params.string());
}

TEST_CASE("run: an empty test set trains, and the best is by train loss", "[train]") {
  Setup<double> s(Method::Regular);
  const Matrix<double> train = spread<double>(6, -0.8), none(1, 0);
  RunSettings settings;
  settings.epochs = 12;
  std::vector<double> train_losses;
  RunCallbacks callbacks;
  callbacks.on_epoch = [&](const EpochRecord& r) {
    CHECK_FALSE(r.test_loss);
    train_losses.push_back(r.train_loss.value());
  };
  const auto result = run_training(s.trainer, train, none, settings, callbacks);
  CHECK(result.end == RunEnd::Finished);
  const auto best = std::min_element(train_losses.begin(), train_losses.end());
  CHECK(result.best_loss == *best);
  CHECK(result.best_epoch == 1 + (best - train_losses.begin()));
  PolynomialPolicy<double> probe({2, 1});
  probe.params() = result.best_params;
  Engine engine(s.sim, probe, to_origin<double>(), 6);
  CHECK(engine.evaluate(train) == result.best_loss);
}

TEST_CASE("trainer: a bad test set is refused before any update", "[train]") {
  Setup<double> s(Method::Regular);
  const Vector<double> before = s.policy.params();
  CHECK_THROWS_WITH(s.trainer.train_epoch(spread<double>(4, 0.1), Matrix<double>(2, 3)),
                    Catch::Contains("test set has 2 rows"));
  CHECK(s.policy.params() == before);
  CHECK(s.trainer.epoch() == 0);
}

TEST_CASE("run: patience stops after that many evaluations without a better loss", "[train]") {
  // A large rate makes Adam overshoot the optimum, so the loss stops improving.
  Setup<double> s(Method::Regular, 3, 0.5);
  const Matrix<double> train = spread<double>(6, -0.8), test = spread<double>(3, 0.5);
  RunSettings settings;
  settings.epochs = 400;
  settings.patience = 4;
  settings.restore_best = true;
  std::vector<double> losses;
  RunCallbacks callbacks;
  callbacks.on_epoch = [&](const EpochRecord& r) { losses.push_back(*r.test_loss); };
  const auto result = run_training(s.trainer, train, test, settings, callbacks);
  REQUIRE(result.end == RunEnd::EarlyStop);
  const auto best = std::min_element(losses.begin(), losses.end());
  CHECK(result.best_epoch == 1 + (best - losses.begin()));
  CHECK(result.epochs == result.best_epoch + 4);
  CHECK(s.policy.params() == result.best_params);
}

TEMPLATE_TEST_CASE("run: a checkpointed run resumed twice ends bit for bit as one run", "[train]",
                   float, double) {
  for (Method method : {Method::Regular, Method::Combined}) {
    const Matrix<TestType> train = spread<TestType>(10, -1.0), test = spread<TestType>(3, 0.2);
    const fs::path whole_log = scratch("whole.csv"), part_log = scratch("part.csv");
    const fs::path checkpoint = scratch("run.checkpoint");
    fs::remove(checkpoint);
    Setup<TestType> whole(method);
    RunSettings settings;
    settings.epochs = 17;
    settings.evaluate_every = 2;
    settings.patience = 50;
    settings.log_csv = whole_log.string();
    run_training(whole.trainer, train, test, settings);

    settings.log_csv = part_log.string();
    settings.checkpoint = checkpoint.string();
    settings.checkpoint_every = 3;
    long resumed_from = 0;
    for (long stop_at : {5L, 11L, 17L}) {  // three processes: the first two end early
      Setup<TestType> part(method);
      settings.epochs = 17;
      RunCallbacks callbacks;
      // Ending at 5 and 11 (not checkpoint epochs) leaves rows after the last checkpoint in
      // the log, as a kill would: the resumed run must cut them.
      callbacks.should_stop = [&](const EpochRecord& r) { return r.epoch == stop_at; };
      const auto result = run_training(part.trainer, train, test, settings, callbacks);
      CHECK(result.resumed_from == resumed_from);
      resumed_from = stop_at;
      if (stop_at == 17) {
        INFO("method " << label(method));
        CHECK(part.policy.params() == whole.policy.params());
        CHECK(without_seconds(file_text(part_log)) == without_seconds(file_text(whole_log)));
        CHECK(part.trainer.optimizer().first_moment() == whole.trainer.optimizer().first_moment());
      }
    }
  }
}

TEST_CASE("run: a stop asked for in the last epoch ends a finished run", "[train]") {
  // Nothing is left to resume: the run is `Finished`, not `Requested` (a program would
  // otherwise tell its user to run it again, and a runner would count it unfinished).
  const Matrix<double> train = spread<double>(6, -1.0), test = spread<double>(2, 0.2);
  for (const bool beside : {false, true}) {
    INFO("evaluate_beside " << beside);
    for (long stop_at : {2L, 3L}) {
      Setup<double> s(Method::Regular, 3);
      RunSettings settings = fresh_checkpoint_run("last.checkpoint", 3);
      settings.evaluate_beside = beside;
      RunCallbacks callbacks;
      callbacks.should_stop = [&](const EpochRecord& r) { return r.epoch == stop_at; };
      const auto result = run_training(s.trainer, train, test, settings, callbacks);
      CHECK(result.epochs == stop_at);
      CHECK(result.end == (stop_at == 3 ? RunEnd::Finished : RunEnd::Requested));
    }
  }
}

TEST_CASE("run: a checkpoint after skipped batches resumes as one run", "[train]") {
  // One train sample overflows the rollout, so the batch that holds it is skipped in every
  // epoch (SkipBatch): Adam has taken one step fewer per epoch than there are batches, which
  // the checkpoint's adam_t must show and a resume must accept. The last epoch's evaluation of
  // the train set is not finite either and stops the run there, resumed or not.
  Matrix<double> train = spread<double>(6, -1.0);
  train(0, 4) = 1e300;
  const Matrix<double> test = spread<double>(2, 0.2);
  const fs::path checkpoint = scratch("skipped.checkpoint");
  fs::remove(checkpoint);
  RunSettings settings;
  settings.epochs = 4;
  settings.evaluate_every = 100;
  Setup<double> whole(Method::Combined, 3, 0.02, NonFinitePolicy::SkipBatch);
  const auto one_run = run_training(whole.trainer, train, test, settings);
  REQUIRE(one_run.end == RunEnd::NonFinite);
  REQUIRE(one_run.epochs == 3);

  settings.checkpoint = checkpoint.string();
  RunCallbacks stop_after_two;  // as a kill would: no evaluation before the stop
  stop_after_two.should_stop = [](const EpochRecord& r) { return r.epoch == 2; };
  Setup<double> first(Method::Combined, 3, 0.02, NonFinitePolicy::SkipBatch);
  REQUIRE(run_training(first.trainer, train, test, settings, stop_after_two).end ==
          RunEnd::Requested);
  CHECK(file_text(checkpoint).find("\nskipped_batches 2\n") != std::string::npos);
  CHECK(file_text(checkpoint).find("\nadam_t 2\n") != std::string::npos);  // 2 × 2 − 2
  Setup<double> second(Method::Combined, 3, 0.02, NonFinitePolicy::SkipBatch);
  const auto resumed = run_training(second.trainer, train, test, settings);
  CHECK(resumed.resumed_from == 2);
  CHECK(resumed.end == RunEnd::NonFinite);
  CHECK(resumed.epochs == 3);
  CHECK(second.policy.params() == whole.policy.params());
}

// Under -Wextra -Werror a string member without an initializer would stop this compiling.
[[maybe_unused]] const RunSettings designated_with_defaults{.epochs = 3};

TEST_CASE("run: a checkpoint of other settings is refused, naming the setting", "[train]") {
  const Matrix<double> train = spread<double>(6, -1.0), test = spread<double>(2, 0.2);
  const fs::path checkpoint = scratch("settings.checkpoint");
  fs::remove(checkpoint);
  RunSettings settings;
  settings.epochs = 2;
  settings.checkpoint = checkpoint.string();
  settings.identity = {{"--poles", "2"}};
  Setup<double> first(Method::Regular, 3);
  run_training(first.trainer, train, test, settings);

  Setup<double> other_batch(Method::Regular, 2);
  CHECK_THROWS_WITH(run_training(other_batch.trainer, train, test, settings),
                    Catch::Contains("was made with batch = 3; this run has batch = 2"));
  // A caller's own name for a trainer setting (a program's flag) is the one the message uses.
  settings.setting_names = {{"batch", "--batch-size"}};
  CHECK_THROWS_WITH(run_training(other_batch.trainer, train, test, settings),
                    Catch::Contains("was made with --batch-size = 3; "
                                    "this run has --batch-size = 2"));
  settings.setting_names = {};
  settings.identity = {{"--poles", "3"}};
  Setup<double> other_flag(Method::Regular, 3);
  CHECK_THROWS_WITH(run_training(other_flag.trainer, train, test, settings),
                    Catch::Contains("--poles = 2; this run has --poles = 3"));
  settings.identity = {{"--poles", "2"}};
  Setup<double> other_data(Method::Regular, 3);
  CHECK_THROWS_WITH(run_training(other_data.trainer, spread<double>(6, -0.9), test, settings),
                    Catch::Contains("train set"));
}

TEST_CASE("run: a caller's setting that the checkpoint could not read back is refused before "
          "any file", "[train]") {
  // A caller's "batch" beside the run's own was written twice, and every resume then refused
  // the checkpoint as damaged; a name with '=' or a value with a line break would not parse.
  const Matrix<double> train = spread<double>(6, -1.0), test = spread<double>(2, 0.2);
  for (const auto& [identity, expected] :
       {std::pair{std::vector<RunSetting>{{"--poles", "2"}, {"batch", "8"}},
                  "run_training: setting 'batch' is in RunSettings::identity and among "
                  "run_training's own settings; expected each name once"},
        std::pair{std::vector<RunSetting>{{"--poles", "2"}, {"--poles", "3"}},
                  "setting '--poles' is in RunSettings::identity twice"},
        std::pair{std::vector<RunSetting>{{"a=b", "1"}},
                  "has setting 'a=b' = '1'; expected a name without '=' or a line break"},
        std::pair{std::vector<RunSetting>{{"note", "two\nlines"}},
                  "; expected a name without '=' or a line break, and a value of one line"}}) {
    RunSettings settings = fresh_checkpoint_run("identity.checkpoint", 2);
    settings.log_csv = scratch("identity.csv").string();
    fs::remove(settings.log_csv);
    settings.identity = identity;
    Setup<double> setup(Method::Regular, 3);
    CHECK_THROWS_WITH(run_training(setup.trainer, train, test, settings),
                      Catch::Contains(expected));
    CHECK_FALSE(fs::exists(settings.checkpoint));
    CHECK_FALSE(fs::exists(settings.checkpoint + ".lock"));
    CHECK_FALSE(fs::exists(settings.log_csv));
  }
}

TEST_CASE("run: the skipped batches of an epoch that ends the run are not counted",
          "[train]") {
  // With skip-batch an epoch whose evaluation is non-finite after a skipped batch ends the
  // run, undone: the result counts the skipped batches of the completed epochs only, as it
  // counts their epochs.
  RunSettings settings;
  settings.epochs = 20;
  std::vector<NonFiniteEvent> events;
  std::vector<bool> skipped;
  RunCallbacks callbacks;
  callbacks.on_non_finite = [&](const NonFiniteEvent& e, bool was_skipped) {
    events.push_back(e);
    skipped.push_back(was_skipped);
  };
  Setup<double> s(Method::Regular, 3, 1e6, NonFinitePolicy::SkipBatch);
  const auto result =
      run_training(s.trainer, spread<double>(6, -1.0), spread<double>(2, 0.2), settings, callbacks);
  REQUIRE(result.end == RunEnd::NonFinite);
  const long last = result.stop_event->epoch;
  long batches_in_last = 0, counted = 0;
  for (std::size_t i = 0; i < events.size(); ++i) {
    if (events[i].epoch == last && events[i].phase == Phase::Update) {
      CHECK(skipped[i]);  // the batch was skipped; the stop follows
      ++batches_in_last;
    }
    if (skipped[i] && events[i].epoch != last) ++counted;
  }
  REQUIRE(batches_in_last >= 1);  // the case this test is about
  CHECK(result.skipped_batches == counted);
}

TEST_CASE("run: a checkpoint cut among its settings is incomplete, not another run's",
          "[train]") {
  // The settings are compared before the numbers are read; a file cut among them must still
  // be called incomplete (exit 1 in the programs), not a checkpoint of other settings (exit 2).
  RunSettings settings = fresh_checkpoint_run("cut_settings.checkpoint", 2);
  const fs::path checkpoint = settings.checkpoint;
  settings.identity = {{"--poles", "2"}};
  Setup<double> first(Method::Regular, 3);
  const Matrix<double> train = spread<double>(6, -1.0), test = spread<double>(2, 0.2);
  run_training(first.trainer, train, test, settings);
  const std::string whole = file_text(checkpoint);
  const std::size_t settings_end = whole.find("\nepoch ") + 1;
  for (std::size_t cut = whole.find('\n') + 1; cut < settings_end; cut += 7) {
    std::ofstream(checkpoint, std::ios::binary | std::ios::trunc) << whole.substr(0, cut);
    INFO("cut after " << cut << " bytes: '" << whole.substr(0, cut) << "'");
    Setup<double> again(Method::Regular, 3);
    RunSettings longer = settings;
    longer.epochs = 3;
    CHECK_THROWS_AS(run_training(again.trainer, train, test, longer), ParseError);
  }
}

TEST_CASE("run: a set of the wrong shape is refused before the log is replaced or on_start",
          "[train]") {
  const fs::path log = scratch("shape.csv");
  const std::string earlier = "a log of another run\n";
  RunSettings settings;
  settings.log_csv = log.string();
  RunCallbacks callbacks;
  bool started = false;
  callbacks.on_start = [&](long) { started = true; };
  const Matrix<double> good = spread<double>(6, -1.0), test = spread<double>(2, 0.2);
  const Matrix<double> two_rows = Matrix<double>::Constant(2, 6, 0.5);  // the state is 1 × 1
  for (const long epochs : {3L, 0L}) {  // with no epoch to run, too
    settings.epochs = epochs;
    std::ofstream(log, std::ios::binary | std::ios::trunc) << earlier;
    Setup<double> s(Method::Regular);
    CHECK_THROWS_WITH(run_training(s.trainer, two_rows, test, settings, callbacks),
                      "run_training: the train set has 2 rows; expected the state dimension 1");
    CHECK_THROWS_WITH(run_training(s.trainer, good, two_rows, settings, callbacks),
                      "run_training: the test set has 2 rows; expected the state dimension 1");
    CHECK_THROWS_WITH(run_training(s.trainer, Matrix<double>(1, 0), test, settings, callbacks),
                      "run_training: the train set has 0 samples; expected at least 1");
    // A non-finite initial state: refused before the epoch it would have spoiled.
    Matrix<double> infinite = test, not_a_number = good;
    infinite(0, 1) = std::numeric_limits<double>::infinity();
    not_a_number(0, 4) = std::numeric_limits<double>::quiet_NaN();
    CHECK_THROWS_WITH(run_training(s.trainer, good, infinite, settings, callbacks),
                      "run_training: the test set has inf in sample 1, entry 0; expected finite "
                      "initial states");
    CHECK_THROWS_WITH(run_training(s.trainer, not_a_number, test, settings, callbacks),
                      "run_training: the train set has nan in sample 4, entry 0; expected finite "
                      "initial states");
    CHECK_FALSE(started);
    CHECK(file_text(log) == earlier);
  }
}

TEST_CASE("run: a double checkpoint resumed in float is refused for its scalar, not parsed",
          "[train]") {
  // Adam's second moments of vanishing gradients can be far below float's range (1e-50); a
  // float run must name the setting that differs, not call the number out of range.
  const RunSettings settings = fresh_checkpoint_run("scalar.checkpoint", 2);
  const fs::path checkpoint = settings.checkpoint;
  Setup<double> first(Method::Regular, 3);
  run_training(first.trainer, spread<double>(6, -1.0), spread<double>(2, 0.2), settings);
  std::string text = file_text(checkpoint);
  const std::size_t moments = text.find("\nadam_v ");
  REQUIRE(moments != std::string::npos);
  const std::size_t value = text.find('\n', moments + 1) + 1;
  text.replace(value, text.find('\n', value) - value, "1e-50");
  std::ofstream(checkpoint, std::ios::binary | std::ios::trunc) << text;
  REQUIRE_NOTHROW(parse_checkpoint<double>(file_text(checkpoint), "scalar.checkpoint"));

  Setup<float> resumed(Method::Regular, 3);
  CHECK_THROWS_AS(run_training(resumed.trainer, spread<float>(6, -1.0f), spread<float>(2, 0.2f),
                               settings),
                  InvalidArgument);
  CHECK_THROWS_WITH(run_training(resumed.trainer, spread<float>(6, -1.0f),
                                 spread<float>(2, 0.2f), settings),
                    Catch::Contains("was made with scalar = double; this run has scalar = float"));
}

TEST_CASE("run: a log that cannot be written still saves the parameters", "[train]") {
  // The file-size limit makes writes past 600 bytes fail with EFBIG, like a full disk.
  const fs::path log = scratch("full.csv"), params = scratch("kept.txt");
  Setup<double> s(Method::Regular);
  RunSettings settings;
  settings.epochs = 200;
  settings.log_csv = log.string();
  settings.save_params = params.string();
  const RestoredLimit restored(RLIMIT_FSIZE);
  const auto old_handler = std::signal(SIGXFSZ, SIG_IGN);
  rlimit small = restored.old;
  small.rlim_cur = 600;
  REQUIRE(setrlimit(RLIMIT_FSIZE, &small) == 0);
  const auto result = run_training(s.trainer, spread<double>(6, -1.0), spread<double>(2, 0.2),
                                   settings);
  REQUIRE(setrlimit(RLIMIT_FSIZE, &restored.old) == 0);
  std::signal(SIGXFSZ, old_handler);
  CHECK(result.end == RunEnd::OutputFailed);
  CHECK_THAT(result.output_error, Catch::Contains("full.csv"));
  CHECK(result.epochs > 1);
  CHECK(result.epochs < 200);
  // The write that failed left no part of its row: the log is the header and the whole rows
  // of the epochs before (a cut row stayed behind, which only a resume from a checkpoint
  // repaired).
  const std::string text = file_text(log);
  REQUIRE(!text.empty());
  CHECK(text.back() == '\n');
  CHECK(std::count(text.begin(), text.end(), '\n') == result.epochs);
  CHECK_THAT(result.output_error, Catch::Contains("the log keeps its whole rows"));
  REQUIRE(result.saved_params == params.string());
  CHECK(load_parameters<double>(params, 2) == s.policy.params());
}

TEST_CASE("run: outputs that are one file are refused before any work", "[train]") {
  const fs::path file = scratch("same.txt");
  fs::remove(file);
  fs::remove(scratch("same_link.txt"));
  std::ofstream(file) << "x\n";
  fs::create_symlink(file, scratch("same_link.txt"));
  Setup<double> s(Method::Regular);
  RunSettings settings;
  settings.epochs = 3;
  settings.log_csv = file.string();
  settings.save_params = scratch("same_link.txt").string();
  CHECK_THROWS_WITH(run_training(s.trainer, spread<double>(4, 0.1), spread<double>(2, 0.1), settings),
                    Catch::Contains("are the same file"));
  CHECK(s.trainer.epoch() == 0);
  settings.save_params = (file.parent_path() / "." / "new.txt").string();
  settings.checkpoint = (file.parent_path() / "new.txt").string();
  CHECK_THROWS_WITH(run_training(s.trainer, spread<double>(4, 0.1), spread<double>(2, 0.1), settings),
                    Catch::Contains("are the same file"));
}

TEST_CASE("run: a descriptor limit too low for the outputs is refused before any work",
          "[train]") {
  // Under `ulimit -n 5` a run with a log, a checkpoint and a parameters file trained its first
  // epoch, could not write that epoch's checkpoint ("Too many open files") and stopped without
  // its parameters saved either. The log and the lock stay open and the first write of a file
  // opens up to two more: four free numbers above the standard streams. The limit is set to the
  // third free number (leaving two: the old code's failure), to the fourth (leaving three: the
  // old code ran, but the removal of a killed writer's temporaries would have found no number),
  // then past it.
  const fs::path dir = fresh_directory("run_descriptors");
  Setup<double> s(Method::Regular);
  RunSettings settings;
  settings.epochs = 2;
  settings.log_csv = (dir / "log.csv").string();
  settings.checkpoint = (dir / "ck").string();
  settings.save_params = (dir / "p.txt").string();
  settings.setting_names = {{"log_csv", "--log"}};
  const std::vector<int> free = detail::free_descriptors_above_standard_streams(4);
  const int third = free[2], fourth = free[3];
  const RestoredLimit restored(RLIMIT_NOFILE);
  REQUIRE((restored.old.rlim_cur == RLIM_INFINITY ||
           static_cast<rlim_t>(fourth) < restored.old.rlim_cur));
  std::optional<RunResult<double>> result;
  const auto run_under = [&](int limit) {
    rlimit lowered = restored.old;
    lowered.rlim_cur = static_cast<rlim_t>(limit);
    REQUIRE(setrlimit(RLIMIT_NOFILE, &lowered) == 0);
    std::string error;
    try {
      result = run_training(s.trainer, spread<double>(4, 0.1), spread<double>(2, 0.1), settings);
    } catch (const IoError& e) {
      error = e.what();
    }
    REQUIRE(setrlimit(RLIMIT_NOFILE, &restored.old) == 0);
    return error;
  };
  CHECK_THAT(run_under(third), Catch::StartsWith("--log, checkpoint and save_params: 4 files") &&
                                   Catch::Contains(" leaves 2 free; expected ulimit -n " +
                                                   std::to_string(fourth + 1) + " or more"));
  CHECK(!result);
  const std::string refused = run_under(fourth);
  CHECK(refused == "--log, checkpoint and save_params: 4 files must be open at once beside the "
                   "standard streams (the log and the checkpoint's lock stay open while the run "
                   "trains, and a write opens up to two: the directory, and the file or a killed "
                   "writer's temporary), but ulimit -n " +
                       std::to_string(fourth) + " leaves 3 free; expected ulimit -n " +
                       std::to_string(fourth + 1) + " or more");
  CHECK(!result);
  CHECK(s.trainer.epoch() == 0);
  CHECK(fs::is_empty(dir));
  CHECK(run_under(fourth + 1).empty());
  REQUIRE(result);
  CHECK(result->end == RunEnd::Finished);
  CHECK(result->output_error.empty());
  CHECK(s.trainer.epoch() == 2);
  for (const char* file : {"log.csv", "ck", "p.txt"}) CHECK(fs::exists(dir / file));
}
