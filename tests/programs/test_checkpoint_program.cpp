// The task programs' checkpoints as a user meets them: refused before any work when past
// --epochs, made with other settings or beside a log the run lacks, each refusal naming the
// flags; a resumed run's loss from the checkpoint. Split from test_task_programs.cpp.
#include <catch2/catch.hpp>

#include <filesystem>
#include <string>

#include "programs/program_runner.hpp"

namespace fs = std::filesystem;
using sbptt::testing::file_text;
using sbptt::testing::Result;
using sbptt::testing::run;
using sbptt::testing::scratch;

TEST_CASE("a checkpoint past --epochs is refused before the initial evaluation; a resumed run "
          "reports its loss from the checkpoint", "[programs]") {
  const fs::path file = scratch("past_epochs.checkpoint");
  fs::remove(file);
  const std::string arguments = "--poles 2 --samples 4 --steps 5 --checkpoint " + file.string();
  const Result first = run("cartpole", arguments + " --epochs 2");
  INFO(first.output);
  REQUIRE(first.status == 0);
  CHECK(first.output.find("initial test loss ") != std::string::npos);

  const Result shorter = run("cartpole", arguments + " --epochs 1");
  INFO(shorter.output);
  CHECK(shorter.status == 2);
  // In the program's words: its flag, not the library's setting or function.
  CHECK(shorter.output.find("cartpole: --checkpoint: checkpoint '" + file.string() +
                            "' is at epoch 2, past --epochs = 1; expected --epochs >= 2") !=
        std::string::npos);
  CHECK(shorter.output.find("run_training") == std::string::npos);
  // The refusal comes before any work: no evaluation was printed.
  CHECK(shorter.output.find("test loss") == std::string::npos);

  // Resumed, the loss printed at the start is that of the checkpoint's parameters, and it
  // equals the test loss the first run logged for its last epoch.
  const Result longer = run("cartpole", arguments + " --epochs 3");
  INFO(longer.output);
  REQUIRE(longer.status == 0);
  CHECK(longer.output.find("initial test loss") == std::string::npos);
  const std::string at_start = "test loss of the resumed parameters ";
  const auto resumed = longer.output.find(at_start);
  REQUIRE(resumed != std::string::npos);
  CHECK(longer.output.find("resuming after epoch 2") < resumed);
  const auto logged = first.output.find("epoch 2  batch ");
  REQUIRE(logged != std::string::npos);
  const auto test_at = first.output.find(" test ", logged);
  REQUIRE(test_at != std::string::npos);
  CHECK(std::stod(longer.output.substr(resumed + at_start.size())) ==
        std::stod(first.output.substr(test_at + 6)));
}

TEST_CASE("a checkpoint's refusals name --checkpoint and the flag of what differs",
          "[programs]") {
  // Found by a fault probe: the initial parameters' mismatch named no flag, and a checkpoint
  // made beside a --csv log resumed without it, the log silently ending at its epoch.
  const fs::path file = scratch("flags.checkpoint"), log = scratch("flags.csv");
  const fs::path params = scratch("flags.params");
  fs::remove(file);
  fs::remove(log);
  const std::string arguments = "--poles 2 --samples 4 --steps 5 --checkpoint " + file.string();
  REQUIRE(run("cartpole", arguments + " --epochs 1 --save-params " + params.string()).status == 0);
  fs::remove(file);
  const Result first = run("cartpole", arguments + " --epochs 2 --csv " + log.string());
  INFO(first.output);
  REQUIRE(first.status == 0);
  const std::string log_text = file_text(log);
  const std::string named = "cartpole: --checkpoint: checkpoint '" + file.string() + "' ";

  const Result other_params =
      run("cartpole", arguments + " --epochs 3 --csv " + log.string() + " --init-params " +
                          params.string());
  INFO(other_params.output);
  CHECK(other_params.status == 2);
  CHECK(other_params.output.find(named + "was made with initial parameters (--init-params' "
                                         "content, else as this build draws them) = ") !=
        std::string::npos);

  const Result no_log = run("cartpole", arguments + " --epochs 3");
  INFO(no_log.output);
  CHECK(no_log.status == 2);
  CHECK(no_log.output.find(named + "was made beside a training log (epochs 1 to 2), and this "
                                   "run has no --csv: the log would stop at epoch 2 while "
                                   "training goes on; expected --csv to name that log") !=
        std::string::npos);
  for (const Result* refused : {&other_params, &no_log}) {
    CHECK(refused->output.find("test loss") == std::string::npos);
    CHECK(refused->output.find("resuming") == std::string::npos);
  }
  CHECK(file_text(log) == log_text);
}
