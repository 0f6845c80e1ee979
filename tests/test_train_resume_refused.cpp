// The training driver (train/run.hpp) refusing to resume, before any work and with the
// trainer as it was: a checkpoint or log changed by hand, a checkpoint without its log, one
// past the epochs asked for, one made without a log, one made beside a log resumed without it,
// and the caller's name for the checkpoint in front of each refusal. Split from
// test_train_run.cpp.
#include <catch2/catch.hpp>

#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include "sbptt/train/run.hpp"
#include "support/files.hpp"
#include "support/linear_trainer.hpp"

using namespace sbptt;
using sbptt::testing::spread;
using sbptt::testing::file_text;
using sbptt::testing::fresh_directory;
namespace fs = std::filesystem;

namespace {

template <class Scalar>
using Setup = sbptt::testing::LinearTrainer<Scalar>;

/// `name` in a directory of this process, emptied once at the first call.
fs::path scratch(const std::string& name) {
  static const fs::path dir = fresh_directory("run_refused");
  return dir / name;
}

/// Settings of a run of `epochs` epochs with its checkpoint at this path (removed), and no log.
RunSettings checkpoint_run(const fs::path& checkpoint, long epochs) {
  fs::remove(checkpoint);
  RunSettings settings;
  settings.epochs = epochs;
  settings.checkpoint = checkpoint.string();
  return settings;
}

/// The same with its log at `log` (left as it is).
RunSettings logged_checkpoint_run(const fs::path& checkpoint, const fs::path& log, long epochs) {
  RunSettings settings = checkpoint_run(checkpoint, epochs);
  settings.log_csv = log.string();
  return settings;
}

}  // namespace

TEST_CASE("run: a checkpoint or log changed by hand is refused before any work, naming what",
          "[train]") {
  // A run of 4 epochs with its checkpoint and log; each case edits one line of the checkpoint
  // (or one row of the log) and resumes towards 6 epochs. Resumed, such a checkpoint cut the
  // log mid-row or repeated epochs, and an impossible Adam state was refused without the file.
  const Matrix<double> train = spread<double>(6, -1.0), test = spread<double>(2, 0.2);
  const fs::path checkpoint = scratch("edited.checkpoint"), log = scratch("edited.csv");
  const RunSettings settings = logged_checkpoint_run(checkpoint, log, 4);
  const auto fresh = [&] {
    fs::remove(checkpoint);
    fs::remove(log);
    Setup<double> s(Method::Combined);
    REQUIRE(run_training(s.trainer, train, test, settings).end == RunEnd::Finished);
  };
  // The first line of `path` that starts with `starts` gets `by` instead of that start (the
  // checkpoint's key and value; the log's epoch, so that its size stays).
  const auto replace_line = [](const fs::path& path, const std::string& starts, const std::string& by) {
    std::istringstream in(file_text(path));
    std::string text, line;
    bool found = false;
    while (std::getline(in, line)) {
      if (!found && line.starts_with(starts)) {
        line = by + (starts.ends_with(",") ? line.substr(starts.size()) : std::string());
        found = true;
      }
      text += line + "\n";
    }
    REQUIRE(found);
    std::ofstream(path, std::ios::trunc) << text;
  };
  struct Case {
    bool edit_log;  ///< else the checkpoint
    std::string starts, by, expected;
    bool names_log;  ///< the message names the log, else the checkpoint
  };
  for (const Case& c : {
           Case{false, "log_bytes ", "log_bytes 100", "do not hold the rows of epochs 1 to 4",
                true},
           Case{false, "epoch ", "epoch 3", "best_epoch 4; expected 0 to 3", false},
           Case{false, "best_epoch ", "best_epoch 9", "best_epoch 9; expected 0 to 4", false},
           Case{false, "adam_t ", "adam_t -1", "adam_t -1; expected 0 to", false},
           Case{false, "since_best ", "since_best -3", "since_best -3; expected 0 to 4", false},
           // Adam's step count without moments, and one this run could not have reached (4
           // epochs of 2 batches: at most 8 steps). Resumed, the first was refused by
           // Adam::restore without the file, the second took other bias corrections.
           Case{false, "adam_t ", "adam_t 0", "adam_t 0 with 2 numbers in adam_m", false},
           Case{false, "adam_t ", "adam_t 9", "adam_t 9 after 4 epochs", false},
           // More skipped batches than the epochs had: "expected at most -992" steps before.
           Case{false, "skipped_batches ", "skipped_batches 1000",
                "skipped_batches 1000 after 4 epochs of 2 batches; expected at most 8", false},
           // The generator's state, refused by Trainer::resume_at without the file.
           Case{false, "shuffle ", "shuffle 42 1 2 3", "not a state of the shuffling", false},
           Case{true, "3,", "7,", "row 3 is missing or does not start with '3,'", true}}) {
    fresh();
    replace_line(c.edit_log ? log : checkpoint, c.starts, c.by);
    INFO((c.edit_log ? "log" : "checkpoint") << ": '" << c.starts << "…' → '" << c.by << "'");
    Setup<double> again(Method::Combined);
    RunSettings longer = settings;
    longer.epochs = 6;
    CHECK_THROWS_WITH(run_training(again.trainer, train, test, longer),
                      Catch::Contains(c.expected) &&
                          Catch::Contains((c.names_log ? log : checkpoint).filename().string()));
  }
  // The last record of another epoch than the checkpoint's (best_epoch left within range).
  fresh();
  replace_line(checkpoint, "best_epoch ", "best_epoch 0");
  replace_line(checkpoint, "since_best ", "since_best 0");
  replace_line(checkpoint, "epoch ", "epoch 3");
  Setup<double> third(Method::Combined);
  CHECK_THROWS_WITH(run_training(third.trainer, train, test, settings),
                    Catch::Contains("edited.checkpoint") &&
                        Catch::Contains("the last record is of epoch 4; expected the "
                                        "checkpoint's epoch 3"));
  // Lines after 'end', which the run never writes.
  fresh();
  std::ofstream(checkpoint, std::ios::app) << "params 1\n0.5\n";
  Setup<double> after_end(Method::Combined);
  CHECK_THROWS_WITH(run_training(after_end.trainer, train, test, settings),
                    Catch::Contains("edited.checkpoint") && Catch::Contains("after 'end'"));
  // A negative second moment, one of adam_v's numbers.
  fresh();
  std::string text = file_text(checkpoint);
  const std::size_t at = text.find("adam_v ");
  REQUIRE(at != std::string::npos);
  const std::size_t entry = text.find('\n', at) + 1;
  text.replace(entry, text.find('\n', entry) - entry, "-1");
  std::ofstream(checkpoint, std::ios::trunc) << text;
  Setup<double> again(Method::Combined);
  CHECK_THROWS_WITH(run_training(again.trainer, train, test, settings),
                    Catch::Contains("edited.checkpoint") &&
                        Catch::Contains("adam_v has a negative entry"));
}

TEST_CASE("run: a checkpoint resumed without its log names the log's setting and says what it "
          "needs, before any work", "[train]") {
  // Found by a fault probe: "cannot open training log '…': No such file or directory" alone
  // named neither the setting (a program's --csv) nor that a checkpoint continues the log it
  // was written beside. Three ways to get there: the log deleted, another log path given, the
  // log of another run given. The trainer must stay as it was (a caller may start over with
  // it), and the log given must stay whole.
  const Matrix<double> train = spread<double>(6, -1.0), test = spread<double>(2, 0.2);
  const fs::path checkpoint = scratch("own_log.checkpoint"), log = scratch("own_log.csv");
  RunSettings settings = logged_checkpoint_run(checkpoint, log, 2);
  settings.setting_names = {{"log_csv", "--csv"}};
  const fs::path short_log = scratch("short_log.csv");
  fs::remove(short_log);
  RunSettings one_epoch = settings;
  one_epoch.checkpoint.clear();
  one_epoch.log_csv = short_log.string();
  one_epoch.epochs = 1;
  Setup<double> short_run(Method::Regular);
  REQUIRE(run_training(short_run.trainer, train, test, one_epoch).end == RunEnd::Finished);
  const std::string short_text = file_text(short_log);
  enum class Given { Deleted, Missing, Other };
  for (const Given given : {Given::Deleted, Given::Missing, Given::Other}) {
    fs::remove(checkpoint);
    fs::remove(log);
    Setup<double> first(Method::Regular);
    REQUIRE(run_training(first.trainer, train, test, settings).end == RunEnd::Finished);
    RunSettings longer = settings;
    longer.epochs = 4;
    if (given == Given::Deleted) fs::remove(log);
    if (given == Given::Missing) longer.log_csv = scratch("missing_log.csv").string();
    if (given == Given::Other) longer.log_csv = short_log.string();
    INFO("log " << static_cast<int>(given) << ": " << longer.log_csv);
    Setup<double> again(Method::Regular);
    const Setup<double> fresh(Method::Regular);
    bool started = false;
    RunCallbacks callbacks;
    callbacks.on_resume = [&](long) { started = true; };
    callbacks.on_start = [&](long) { started = true; };
    const std::string named = "--csv '" + longer.log_csv + "': ";
    if (given == Given::Other) {
      CHECK_THROWS_WITH(run_training(again.trainer, train, test, longer, callbacks),
                        Catch::Contains(named) &&
                            Catch::Contains("the checkpoint expects at least"));
      CHECK(file_text(short_log) == short_text);
    } else {
      CHECK_THROWS_WITH(
          run_training(again.trainer, train, test, longer, callbacks),
          Catch::Contains(named + "No such file or directory; checkpoint '" + checkpoint.string() +
                          "' continues the training log it was written beside (epochs 1 to 2); "
                          "expected --csv to name that log, or no checkpoint to start over"));
      CHECK_FALSE(fs::exists(longer.log_csv));
    }
    CHECK_FALSE(started);
    CHECK(again.trainer.epoch() == 0);
    CHECK(again.policy.params() == fresh.policy.params());
  }
}

TEST_CASE("run: a checkpoint past the epochs asked for is refused before any work", "[train]") {
  // Resumed, the run of 4 epochs ended at once as if it had trained 2, and saved the
  // parameters of epoch 4 in place of epoch 2's.
  const Matrix<double> train = spread<double>(6, -1.0), test = spread<double>(2, 0.2);
  const fs::path checkpoint = scratch("past.checkpoint"), log = scratch("past.csv");
  const fs::path params = scratch("past_params.txt");
  for (const auto& path : {checkpoint, log, params}) fs::remove(path);
  RunSettings settings;
  settings.epochs = 4;
  settings.checkpoint = checkpoint.string();
  settings.log_csv = log.string();
  // on_start: after every check and the resume, before the first epoch, with the epochs done.
  std::vector<std::string> calls;
  RunCallbacks callbacks;
  callbacks.on_resume = [&](long epoch) { calls.push_back("resume " + std::to_string(epoch)); };
  callbacks.on_start = [&](long epoch) { calls.push_back("start " + std::to_string(epoch)); };
  callbacks.on_epoch = [&](const EpochRecord& r) {
    calls.push_back("epoch " + std::to_string(r.epoch));
  };
  Setup<double> first(Method::Regular);
  REQUIRE(run_training(first.trainer, train, test, settings, callbacks).end ==
          RunEnd::Finished);
  const std::string checkpoint_text = file_text(checkpoint), log_text = file_text(log);

  Setup<double> shorter(Method::Regular);
  settings.epochs = 2;
  settings.save_params = params.string();
  CHECK_THROWS_WITH(run_training(shorter.trainer, train, test, settings, callbacks),
                    Catch::Contains("past.checkpoint") && Catch::Contains("epoch 4") &&
                        Catch::Contains("epochs = 2") && Catch::Contains("expected epochs >= 4"));
  CHECK(file_text(checkpoint) == checkpoint_text);
  CHECK(file_text(log) == log_text);
  CHECK(!fs::exists(params));

  // As many epochs as the checkpoint holds: a finished run, nothing trained.
  Setup<double> same(Method::Regular);
  settings.epochs = 4;
  const auto result = run_training(same.trainer, train, test, settings, callbacks);
  CHECK(calls == std::vector<std::string>{"start 0", "epoch 1", "epoch 2", "epoch 3", "epoch 4",
                                          "resume 4", "start 4"});
  CHECK(result.resumed_from == 4);
  CHECK(result.epochs == 4);
  CHECK(same.policy.params() == first.policy.params());
  CHECK(file_text(log) == log_text);
}

TEST_CASE("run: a checkpoint made without a log is refused with a log, before resuming",
          "[train]") {
  // It was an IoError (exit 1 in the programs, as for a failed write) thrown after on_resume
  // had announced the resume; it is a setting of the run that differs.
  const Matrix<double> train = spread<double>(6, -1.0), test = spread<double>(2, 0.2);
  const fs::path checkpoint = scratch("no_log.checkpoint"), log = scratch("no_log.csv");
  fs::remove(log);
  RunSettings settings = checkpoint_run(checkpoint, 2);
  Setup<double> first(Method::Regular);
  REQUIRE(run_training(first.trainer, train, test, settings).end == RunEnd::Finished);

  Setup<double> again(Method::Regular);
  settings.epochs = 4;
  settings.log_csv = log.string();
  bool announced = false;
  RunCallbacks callbacks;
  callbacks.on_resume = [&](long) { announced = true; };
  CHECK_THROWS_AS(run_training(again.trainer, train, test, settings, callbacks),
                  InvalidArgument);
  CHECK_THROWS_WITH(run_training(again.trainer, train, test, settings, callbacks),
                    Catch::Contains("made without a training log"));
  CHECK_FALSE(announced);
  CHECK_FALSE(fs::exists(log));
}

TEST_CASE("run: a checkpoint made beside a log is refused without one, naming the log's "
          "setting, before resuming", "[train]") {
  // Found by a fault probe: resumed without its log, the run went on and the log silently
  // ended at the checkpoint's epoch. The mirror of the case above.
  const Matrix<double> train = spread<double>(6, -1.0), test = spread<double>(2, 0.2);
  const fs::path checkpoint = scratch("with_log.checkpoint"), log = scratch("with_log.csv");
  fs::remove(log);
  RunSettings settings = logged_checkpoint_run(checkpoint, log, 2);
  settings.setting_names = {{"log_csv", "--csv"}};
  Setup<double> first(Method::Regular);
  REQUIRE(run_training(first.trainer, train, test, settings).end == RunEnd::Finished);
  const std::string log_text = file_text(log);
  const std::string checkpoint_text = file_text(checkpoint);

  // Rerun finished, it trains nothing and its log lacks nothing: that goes on.
  settings.log_csv.clear();
  Setup<double> rerun(Method::Regular);
  CHECK(run_training(rerun.trainer, train, test, settings).end == RunEnd::Finished);
  CHECK(rerun.policy.params() == first.policy.params());
  CHECK(file_text(log) == log_text);

  Setup<double> again(Method::Regular);
  const Setup<double> fresh(Method::Regular);
  settings.epochs = 4;
  bool started = false;
  RunCallbacks callbacks;
  callbacks.on_resume = [&](long) { started = true; };
  callbacks.on_start = [&](long) { started = true; };
  CHECK_THROWS_AS(run_training(again.trainer, train, test, settings, callbacks),
                  InvalidArgument);
  CHECK_THROWS_WITH(run_training(again.trainer, train, test, settings, callbacks),
                    Catch::Contains("checkpoint '" + checkpoint.string() +
                                    "' was made beside a training log (epochs 1 to 2), and this "
                                    "run has no --csv: the log would stop at epoch 2 while "
                                    "training goes on; expected --csv to name that log"));
  CHECK_FALSE(started);
  CHECK(again.trainer.epoch() == 0);
  CHECK(again.policy.params() == fresh.policy.params());
  CHECK(file_text(log) == log_text);
  CHECK(file_text(checkpoint) == checkpoint_text);
}

TEST_CASE("run: the caller's name for the checkpoint leads every refusal of it", "[train]") {
  // Found by a fault probe: a program's refusals said "checkpoint '…'", never --checkpoint.
  const Matrix<double> train = spread<double>(6, -1.0), test = spread<double>(2, 0.2);
  const fs::path checkpoint = scratch("named.checkpoint");
  RunSettings settings = checkpoint_run(checkpoint, 2);
  Setup<double> first(Method::Regular);
  REQUIRE(run_training(first.trainer, train, test, settings).end == RunEnd::Finished);

  settings.setting_names = {{"checkpoint", "--checkpoint"}, {"epochs", "--epochs"}};
  const std::string named = "--checkpoint: checkpoint '" + checkpoint.string() + "'";
  settings.epochs = 1;  // past --epochs: a check of the resume
  Setup<double> shorter(Method::Regular);
  CHECK_THROWS_AS(run_training(shorter.trainer, train, test, settings), InvalidArgument);
  CHECK_THROWS_WITH(run_training(shorter.trainer, train, test, settings),
                    Catch::StartsWith(named + " is at epoch 2, past --epochs = 1"));
  settings.epochs = 4;
  Setup<double> other(Method::Modified);  // another setting: a check while loading
  CHECK_THROWS_AS(run_training(other.trainer, train, test, settings), InvalidArgument);
  CHECK_THROWS_WITH(run_training(other.trainer, train, test, settings),
                    Catch::StartsWith(named + " was made with method = "));
  {
    // Held by another run: the lock's refusal (the same process cannot take it twice).
    const detail::FileLock held = lock_checkpoint(checkpoint.string());
    Setup<double> twice(Method::Regular);
    CHECK_THROWS_AS(run_training(twice.trainer, train, test, settings), IoError);
    CHECK_THROWS_WITH(run_training(twice.trainer, train, test, settings),
                      Catch::StartsWith(named + " is in use"));
  }
  std::ofstream(checkpoint, std::ios::trunc) << "not a checkpoint\n";
  Setup<double> garbled(Method::Regular);
  CHECK_THROWS_AS(run_training(garbled.trainer, train, test, settings), ParseError);
  CHECK_THROWS_WITH(run_training(garbled.trainer, train, test, settings),
                    Catch::StartsWith("--checkpoint: '" + checkpoint.string() +
                                      "' is not an sbptt checkpoint"));
}

TEST_CASE("run: a checkpoint of another horizon, loss timing or loss weight is refused",
          "[train]") {
  // The checkpoint recorded none of them: a run of horizon 6 resumed with horizon 3 without a
  // word, its log then mixing two problems.
  using testing::LinearLoss;
  const Matrix<double> train = spread<double>(6, -1.0), test = spread<double>(2, 0.2);
  const fs::path checkpoint = scratch("objective.checkpoint");
  {
    Setup<double> first(Method::Regular);
    REQUIRE(run_training(first.trainer, train, test, checkpoint_run(checkpoint, 2)).end ==
            RunEnd::Finished);
  }
  const auto resume = [&](Index steps, const Objective<LinearLoss<double>>& objective) {
    Setup<double> s(Method::Regular);
    Trainer trainer(s.sim, s.policy, objective, steps, Adam<double>(AdamOptions<double>{0.02}),
                    Setup<double>::options(Method::Regular, 3, NonFinitePolicy::Stop));
    RunSettings settings;
    settings.epochs = 3;
    settings.checkpoint = checkpoint.string();
    return run_training(trainer, train, test, settings).epochs;  // refused before any work
  };
  auto objective = testing::to_origin<double>();
  CHECK_THROWS_WITH(resume(3, objective),
                    Catch::Contains("was made with steps = 6; this run has steps = 3"));
  objective.timing = LossTiming::Final;
  CHECK_THROWS_WITH(resume(6, objective),
                    Catch::Contains("was made with loss_timing = continuous; this run has "
                                    "loss_timing = final"));
  objective = testing::to_origin<double>();
  objective.step_weight = 0.5;
  CHECK_THROWS_WITH(resume(6, objective),
                    Catch::Contains("was made with step_weight = 1; this run has step_weight = "
                                    "0.5"));
  objective = testing::to_origin<double>();
  objective.control_weight = 0.25;
  CHECK_THROWS_WITH(resume(6, objective),
                    Catch::Contains("was made with control_weight = 0; this run has "
                                    "control_weight = 0.25"));
  // A checkpoint of this run written before these settings were recorded says so.
  const std::string written = file_text(checkpoint);
  std::string older;
  std::istringstream lines(written);
  for (std::string line; std::getline(lines, line);)
    if (!line.starts_with("setting steps=") && !line.starts_with("setting loss_timing=") &&
        !line.starts_with("setting step_weight=") && !line.starts_with("setting control_weight="))
      older += line + "\n";
  REQUIRE(older.size() < written.size());
  std::ofstream(checkpoint) << older;
  CHECK_THROWS_WITH(resume(6, testing::to_origin<double>()),
                    Catch::Contains("has no setting steps (this run has steps = 6): it was "
                                    "written before 2026-12-07"));
  std::ofstream(checkpoint) << written;
  CHECK(resume(6, testing::to_origin<double>()) == 3);
}

TEST_CASE("run: a controller with a non-finite parameter is refused before any work", "[train]") {
  // It started, stopped on a non-finite control in epoch 1 and then ended as OutputFailed
  // ("save_parameters: parameter 1 is nan"), the cause only in the stop event.
  const Matrix<double> train = spread<double>(6, -1.0), test = spread<double>(2, 0.2);
  Setup<double> s(Method::Regular);
  s.policy.params()(1) = -std::numeric_limits<double>::quiet_NaN();
  RunSettings settings;
  settings.epochs = 2;
  settings.save_params = scratch("nan.params").string();
  bool started = false;
  RunCallbacks callbacks;
  callbacks.on_start = [&](long) { started = true; };
  CHECK_THROWS_WITH(run_training(s.trainer, train, test, settings, callbacks),
                    "run_training: the controller's parameter 1 is nan; expected finite "
                    "initial parameters");
  CHECK_FALSE(started);
  CHECK_FALSE(fs::exists(settings.save_params));
}
