// The checkpoint file on its own (train/checkpoint.hpp): what reads back, what is refused and
// with which line, one run per checkpoint at a time, and the files of a run opened while
// stderr is closed. The runs that write and resume checkpoints are in test_train_run.cpp.
#include <catch2/catch.hpp>

#include <unistd.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "sbptt/core/atomic_file.hpp"
#include "sbptt/core/rng.hpp"
#include "sbptt/train/checkpoint.hpp"
#include "sbptt/train/run.hpp"
#include "sbptt/train/training_log.hpp"
#include "support/files.hpp"
#include "support/linear_trainer.hpp"

using namespace sbptt;
using sbptt::testing::file_text;
using sbptt::testing::fresh_directory;
namespace fs = std::filesystem;

namespace {

/// `name` in a directory of this process, emptied once at the first call.
fs::path scratch(const std::string& name) {
  static const fs::path dir = fresh_directory("checkpoint");
  return dir / name;
}

}  // namespace

TEST_CASE("checkpoint: an epoch whose squared update norm overflowed reads back", "[train]") {
  // A double gradient of norm 1e200 is finite and clips correctly; its square is +inf, and the
  // log says so. The checkpoint written after that epoch must still resume the run.
  Checkpoint<double> c;
  c.shuffle_state = Rng(1).state();
  c.epoch = 7;
  c.last = EpochRecord{};
  c.last->epoch = 7;
  c.last->update_norm2 = std::numeric_limits<double>::infinity();
  const Checkpoint<double> back = parse_checkpoint<double>(checkpoint_text(c), "test.checkpoint");
  REQUIRE(back.last);
  CHECK(back.last->epoch == 7);
  CHECK(back.last->update_norm2 == std::numeric_limits<double>::infinity());
  c.last->update_norm2 = std::numeric_limits<double>::quiet_NaN();  // never a squared norm
  CHECK_THROWS_AS(parse_checkpoint<double>(checkpoint_text(c), "test.checkpoint"), ParseError);
}

TEST_CASE("checkpoint: a count of numbers beyond the lines left is refused before reading",
          "[train]") {
  // 'params 100000000' made the reader allocate 10^8 numbers before finding the file short:
  // under a memory limit that was reported as running out of memory for the run's sizes.
  Checkpoint<double> c;
  c.shuffle_state = Rng(1).state();
  c.epoch = 1;
  c.params = Vector<double>::Constant(3, 0.5);
  const std::string text = checkpoint_text(c);
  REQUIRE_NOTHROW(parse_checkpoint<double>(text, "test.checkpoint"));
  const auto lines_after = [&](const std::string& key) {
    const std::size_t at = text.find("\n" + key + " ") + 1;
    return std::count(text.begin() + static_cast<std::ptrdiff_t>(at), text.end(), '\n') - 1;
  };
  for (const std::string key : {"params", "best_params", "adam_m", "adam_v"}) {
    std::string spoiled = text;
    const std::size_t at = spoiled.find("\n" + key + " ") + 1;
    spoiled.replace(at, spoiled.find('\n', at) - at, key + " 100000000");
    INFO(key);
    CHECK_THROWS_WITH(parse_checkpoint<double>(spoiled, "test.checkpoint"),
                      Catch::Contains(": 100000000 numbers in " + key + "; expected at most the " +
                                      std::to_string(lines_after(key)) +
                                      " lines left in the file"));
  }
}

TEST_CASE("checkpoint: the last record's epoch is a whole number in range, or refused",
          "[train]") {
  // 1.5 was read as epoch 1, and 1e300 converted to a long out of its range (undefined).
  Checkpoint<double> c;
  c.shuffle_state = Rng(1).state();
  c.epoch = 1;
  c.last = EpochRecord{};
  c.last->epoch = 1;
  const std::string text = checkpoint_text(c);
  REQUIRE_NOTHROW(parse_checkpoint<double>(text, "test.checkpoint"));
  for (const auto& [epoch, expected] :
       {std::pair{"1.5", "expected a whole number for 'epoch of last'"},
        std::pair{"1e300", "e+300; expected 0 to 1000000000000000"},
        std::pair{"-1e300", "e+300; expected 0 to 1000000000000000"},
        std::pair{"1e19", "epoch of last 1e+19; expected 0 to 1000000000000000"}}) {
    std::string spoiled = text;
    spoiled.replace(spoiled.find("\nlast 1 ") + 6, 1, epoch);
    INFO(spoiled.substr(spoiled.find("\nlast"), 40));
    CHECK_THROWS_WITH(parse_checkpoint<double>(spoiled, "test.checkpoint"),
                      Catch::Contains(expected));
  }
}

TEST_CASE("checkpoint: an error names the line that is wrong, whichever it is", "[train]") {
  // Every line but the first (the magic line has its own message) is spoiled in turn: a
  // number becomes 'x', a key's value becomes 'x'. The message must name that line; numbers
  // were reported one line early (the line was counted after the message was made).
  Checkpoint<double> c;
  c.settings = {{"method", "C"}};
  c.shuffle_state = Rng(1).state();
  c.epoch = 3;
  c.adam_t = 6;
  c.params = Vector<double>::Constant(3, 0.5);
  c.best_epoch = 2;
  c.best_params = c.params;
  c.adam_m = Vector<double>::Constant(3, 0.25);
  c.adam_v = c.adam_m;
  c.last = EpochRecord{};
  c.last->epoch = 3;
  const std::string text = checkpoint_text(c);
  std::vector<std::string> lines;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  REQUIRE(lines.size() > 20);
  for (std::size_t k = 1; k < lines.size(); ++k) {
    std::vector<std::string> spoiled = lines;
    const std::size_t space = spoiled[k].find(' ');
    spoiled[k] = space == std::string::npos ? "x" : spoiled[k].substr(0, space + 1) + "x";
    std::string broken;
    for (const auto& line : spoiled) broken += line + "\n";
    const std::string line_number = "line " + std::to_string(k + 1) + ":";
    INFO("line " << k + 1 << " '" << lines[k] << "' spoiled as '" << spoiled[k] << "'");
    CHECK_THROWS_WITH(parse_checkpoint<double>(broken, "test.checkpoint"),
                      Catch::Contains("checkpoint 'test.checkpoint', " + line_number));
  }
  // A last line without its end names that line, not the one before.
  const std::string cut = text.substr(0, text.size() - 1);
  CHECK_THROWS_WITH(parse_checkpoint<double>(cut, "test.checkpoint"),
                    Catch::Contains("line " + std::to_string(lines.size()) + ": the line has no end"));
}

TEST_CASE("checkpoint: a setting given twice is refused, naming both lines", "[train]") {
  // A second line of a setting was read, and the last one won: a hand-edited --samples=64
  // after the run's --samples=32 was compared, before it was not. The program never writes
  // a setting twice.
  Checkpoint<double> c;
  c.settings = {{"method", "C"}, {"--samples", "32"}};
  c.shuffle_state = Rng(1).state();
  c.epoch = 1;
  const std::string text = checkpoint_text(c);
  REQUIRE_NOTHROW(parse_checkpoint<double>(text, "test.checkpoint"));
  for (const char* second : {"setting --samples=64\n", "setting --samples=32\n"}) {
    std::string doubled = text;
    doubled.insert(doubled.find("setting --samples"), second);
    INFO(doubled.substr(0, 120));
    CHECK_THROWS_WITH(parse_checkpoint<double>(doubled, "test.checkpoint"),
                      Catch::Contains("checkpoint 'test.checkpoint', line 4: setting --samples "
                                      "again (line 3 gave it); expected each setting once"));
  }
}

TEST_CASE("checkpoint: the file's own text is echoed with its control bytes escaped",
          "[train]") {
  // A damaged or hostile file must not drive the terminal (ESC sequences) or cut the message
  // (a NUL ends a C string in fprintf); what follows the value must still be said.
  const std::string hostile = std::string("3\x1b[2J") + '\0' + "7";
  const std::string shown = "3\\x1b[2J\\x007";
  auto without_control_bytes = [](const std::string& message) {
    return std::ranges::none_of(message, [](char c) {
      return static_cast<unsigned char>(c) < 0x20 || c == 0x7f;
    });
  };
  auto message_of = [](auto&& call) {
    try {
      call();
    } catch (const std::exception& e) {
      return std::string(e.what(), std::strlen(e.what()));
    }
    return std::string("(nothing thrown)");
  };
  Checkpoint<double> c;
  c.settings = {{"method", "C"}, {"--samples", hostile}, {hostile, "1"}};
  c.shuffle_state = Rng(1).state();
  c.epoch = 1;
  const std::string text = checkpoint_text(c);
  const Checkpoint<double> read = parse_checkpoint<double>(text, "test.checkpoint");
  REQUIRE(read.settings[1].value == hostile);

  const std::string other_value = message_of([&] {
    require_same_settings({{"method", "C"}, {"--samples", "32"}}, read.settings, "c");
  });
  INFO(other_value);
  CHECK(without_control_bytes(other_value));
  CHECK_THAT(other_value, Catch::Contains("--samples = " + shown + "; this run has --samples = 32"));

  const std::string unknown = message_of([&] {
    require_same_settings({{"method", "C"}, {"--samples", hostile}}, read.settings, "c");
  });
  INFO(unknown);
  CHECK(without_control_bytes(unknown));
  CHECK_THAT(unknown, Catch::Contains("made with setting " + shown + " = 1, which this run"));

  std::string twice = text;
  twice.insert(twice.find("setting method"), "setting " + hostile + "=1\n");
  const std::string again =
      message_of([&] { (void)parse_checkpoint<double>(twice, "test.checkpoint"); });
  INFO(again);
  CHECK(without_control_bytes(again));
  CHECK_THAT(again, Catch::Contains("setting " + shown + " again (line 2 gave it)"));

  std::string wrong_key = text;
  wrong_key.replace(wrong_key.find("epoch 1"), 5, hostile);
  const std::string key =
      message_of([&] { (void)parse_checkpoint<double>(wrong_key, "test.checkpoint"); });
  INFO(key);
  CHECK(without_control_bytes(key));
  CHECK_THAT(key, Catch::Contains(shown + " 1', expected 'epoch"));
}

TEST_CASE("checkpoint: best parameters exactly when an epoch was best, or refused", "[train]") {
  // A run keeps θ of its best epoch from the first evaluation on, and none before it; resumed
  // with best_epoch > 0 and no best_params, restore_best emptied the controller.
  Checkpoint<double> c;
  c.shuffle_state = Rng(1).state();
  c.epoch = 3;
  c.params = Vector<double>::Constant(3, 0.5);
  c.best_epoch = 2;
  c.best_params = Vector<double>::Constant(3, 0.25);
  REQUIRE_NOTHROW(parse_checkpoint<double>(checkpoint_text(c), "test.checkpoint"));
  c.best_params.resize(0);
  CHECK_THROWS_WITH(parse_checkpoint<double>(checkpoint_text(c), "test.checkpoint"),
                    Catch::Contains("best_epoch 2 with 0 numbers in best_params"));
  c.best_epoch = 0;
  REQUIRE_NOTHROW(parse_checkpoint<double>(checkpoint_text(c), "test.checkpoint"));
  c.best_params = c.params;
  CHECK_THROWS_WITH(parse_checkpoint<double>(checkpoint_text(c), "test.checkpoint"),
                    Catch::Contains("best_epoch 0 with 3 numbers in best_params"));
}

TEST_CASE("checkpoint: a second run of a checkpoint in use is refused before any work",
          "[train]") {
  // The same command started twice: both trained, their rows interleaved in the log, and no
  // later run could resume from it. The second run here starts while the first is in its
  // epoch 2 (flock locks of two opens conflict within one process as between two).
  using sbptt::testing::LinearTrainer;
  using sbptt::testing::spread;
  LinearTrainer<double> first(Method::Combined), second(Method::Combined);
  const Matrix<double> train = spread<double>(9, -1.0), test = spread<double>(4, 0.3);
  RunSettings settings;
  settings.epochs = 3;
  settings.checkpoint = scratch("shared.checkpoint").string();
  settings.log_csv = scratch("shared.csv").string();
  fs::remove(settings.checkpoint);
  bool refused = false;
  RunCallbacks callbacks;
  callbacks.on_epoch = [&](const EpochRecord& record) {
    if (record.epoch != 1) return;
    const std::string log_before = file_text(settings.log_csv);
    RunCallbacks second_callbacks;
    second_callbacks.on_start = [](long) { FAIL("the second run started"); };
    try {
      (void)run_training(second.trainer, train, test, settings, second_callbacks);
    } catch (const IoError& e) {
      refused = true;
      CHECK_THAT(e.what(), Catch::Contains("checkpoint '" + settings.checkpoint + "' is in use") &&
                               Catch::Contains(settings.checkpoint + ".lock") &&
                               Catch::Contains("expected one run per checkpoint"));
    }
    CHECK(file_text(settings.log_csv) == log_before);
    CHECK(second.trainer.epoch() == 0);
  };
  const auto result = run_training(first.trainer, train, test, settings, callbacks);
  CHECK(refused);
  CHECK(result.end == RunEnd::Finished);
  // The lock ends with the run: the checkpoint resumes (its last epoch is the run's end).
  const auto resumed = run_training(second.trainer, train, test, settings);
  CHECK(resumed.end == RunEnd::Finished);
  CHECK(second.trainer.epoch() == 3);
}

TEST_CASE("checkpoint: a log or parameters file in the place of its lock is refused", "[train]") {
  // `--csv ck.lock --checkpoint ck`: the log's first write renamed a new file over the lock,
  // so a second run of the same command locked another inode and both trained on one
  // checkpoint (found by a fault probe of the task programs).
  using sbptt::testing::LinearTrainer;
  using sbptt::testing::spread;
  LinearTrainer<double> run(Method::Combined);
  const Matrix<double> train = spread<double>(9, -1.0), test = spread<double>(4, 0.3);
  RunSettings settings;
  settings.epochs = 2;
  settings.checkpoint = scratch("own_lock.checkpoint").string();
  fs::remove(settings.checkpoint);
  for (std::string* output : {&settings.log_csv, &settings.save_params}) {
    *output = settings.checkpoint + ".lock";
    CHECK_THROWS_WITH(run_training(run.trainer, train, test, settings),
                      Catch::Contains("' and checkpoint's lock file '" + settings.checkpoint +
                                      ".lock' are the same file"));
    CHECK_FALSE(fs::exists(settings.checkpoint));
    CHECK(run.trainer.epoch() == 0);
    output->clear();
  }
}

TEST_CASE("files opened while stderr is closed do not take its number", "[train]") {
  // A program started with `2>&-`: the first file it opened got fd 2, and every message meant
  // for stderr landed in its training log (found by a fault probe of the task programs).
  const fs::path log = scratch("closed_stderr.csv"), other = scratch("closed_stderr.txt");
  fs::remove(log);
  const int saved = ::dup(2);
  REQUIRE(saved >= 0);
  ::close(2);
  bool wrote = false;
  try {
    TrainingLogFile file = TrainingLogFile::create(log.string());
    AtomicFile atomic(other.string());
    const char message[] = "a message for stderr\n";
    wrote = ::write(2, message, sizeof message - 1) > 0;
    atomic.write("content\n");
    atomic.commit();
  } catch (...) {
    ::dup2(saved, 2);
    ::close(saved);
    throw;
  }
  ::dup2(saved, 2);
  ::close(saved);
  CHECK_FALSE(wrote);
  CHECK(file_text(log) == std::string(training_log_header) + "\n");
  CHECK(file_text(other) == "content\n");
}
