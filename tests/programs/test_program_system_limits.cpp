// What the programs do when the system says no: threads it will not start (a process limit,
// played by support/thread_start_fails.cpp), and a reader that went away (`| head`). Either
// used to end a run without a word (a hang, an abort, or death by SIGPIPE with the parameters
// unsaved); now each ends with exit 1 and, where stderr still reaches someone, says why.
//
// SBPTT_EXAMPLES_DIR (environment) runs these tests against other builds of the programs.
#include <catch2/catch.hpp>

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <string>
#include <utility>
#include <vector>

#include "programs/program_runner.hpp"
#include "support/address_sanitizer.hpp"
#include "support/files.hpp"

namespace fs = std::filesystem;
using sbptt::testing::examples_dir;
using sbptt::testing::file_text;
using sbptt::testing::fresh_directory;

namespace {

/// Runs `command` through `sh -c` (under `timeout 120`: a program that blocked would fail, not
/// hang the suite) with stdout, and stderr unless the command redirects it, on a pipe whose
/// reading end is already closed: every write to it fails (or raises SIGPIPE). Returns the wait
/// status.
int run_into_closed_pipe(const std::string& command) {
  int ends[2];
  REQUIRE(::pipe(ends) == 0);
  ::close(ends[0]);
  const pid_t pid = ::fork();
  REQUIRE(pid >= 0);
  if (pid == 0) {
    ::signal(SIGPIPE, SIG_DFL);  // as a shell starts a pipeline's programs
    ::dup2(ends[1], 1);
    ::dup2(ends[1], 2);
    ::close(ends[1]);
    const std::string timed = "exec timeout 120 " + command;
    ::execl("/bin/sh", "sh", "-c", timed.c_str(), static_cast<char*>(nullptr));
    ::_exit(127);
  }
  ::close(ends[1]);
  int status = 0;
  REQUIRE(::waitpid(pid, &status, 0) == pid);
  return status;
}

std::string describe_status(int status) {
  if (WIFSIGNALED(status)) return "killed by signal " + std::to_string(WTERMSIG(status));
  return "exit " + std::to_string(WEXITSTATUS(status));
}

}  // namespace

TEST_CASE("a reader that went away: the run finishes its files and exits 1, not by SIGPIPE",
          "[programs]") {
  // `guidance … 2>&1 | head -2` died at its next line with exit 141, its log one row long and
  // --save-params never written.
  const fs::path dir = fresh_directory("closed_pipe");
  const std::string params = (dir / "p.txt").string(), log = (dir / "log.csv").string();
  const std::string run = examples_dir() + "/guidance --epochs 3 --samples 16 --csv " + log +
                          " --save-params " + params;
  int status = run_into_closed_pipe(run);
  INFO(describe_status(status));
  CHECK((WIFEXITED(status) && WEXITSTATUS(status) == 1));
  CHECK(fs::exists(params));
  const std::string rows = file_text(log);
  CHECK(std::count(rows.begin(), rows.end(), '\n') == 4);  // the header and 3 epochs

  // With stderr elsewhere, it says why.
  const std::string said = (dir / "stderr.txt").string();
  fs::remove(params);
  fs::remove(log);
  status = run_into_closed_pipe(run + " 2>" + said);
  INFO(describe_status(status) << "\n" << file_text(said));
  CHECK((WIFEXITED(status) && WEXITSTATUS(status) == 1));
  CHECK(file_text(said).find("guidance: standard output or standard error was not written in "
                             "full: Broken pipe") != std::string::npos);
  CHECK(fs::exists(params));

  // Every program's usage into a closed pipe: exit 1, none killed.
  for (const std::string program :
       {"toy", "cartpole", "guidance", "quantum", "mujoco", "rotation", "accuracy",
        "lqr_convergence", "bench", "bench_mujoco", "reproduce"}) {
    status = run_into_closed_pipe(examples_dir() + "/" + program + " --help");
    INFO(program << ": " << describe_status(status));
    CHECK((WIFEXITED(status) && WEXITSTATUS(status) == 1));
  }
  for (const std::string program : {"custom_simulator", "train_own_scene"}) {
    const std::string arguments =
        program == "train_own_scene" ? fresh_directory("closed_pipe_own_scene").string() : "";
    status = run_into_closed_pipe(examples_dir() + "/" + program + " " + arguments);
    INFO(program << ": " << describe_status(status));
    CHECK((WIFEXITED(status) && WEXITSTATUS(status) == 1));
  }

  // The runner finishes its sweep (it died at its next line, killing its runs), and its task
  // programs get SIGPIPE back as they would from a shell (it passed its own ignoring on).
  const fs::path out = dir / "sweep";
  status = run_into_closed_pipe(examples_dir() + "/reproduce --tasks cartpole --complexities 1 "
                                "--methods R --clips norm --seeds 1 --epochs 2 --samples 8 "
                                "--no-plot --out " + out.string());
  INFO("reproduce: " << describe_status(status));
  CHECK((WIFEXITED(status) && WEXITSTATUS(status) == 1));
  const std::string summary = file_text(out / "summary.csv");
  CHECK(std::count(summary.begin(), summary.end(), '\n') == 2);  // the header and the run
}

TEST_CASE("threads the system will not start: exit 1 naming --threads, no hang, no abort",
          "[programs]") {
#ifndef SBPTT_THREAD_START_FAILS
  WARN("built without the thread-start shim (a sanitizer build): not checked");
#else
  if (sbptt::testing::address_sanitizer) {
    WARN("AddressSanitizer must be the first library: the shim cannot be preloaded");
    return;
  }
  // Under ulimit -u or a pids limit the pool's constructor threw with its started workers
  // still joinable: std::terminate (exit 134) when one had started, a hang for ever when many.
  const std::string shim = std::string("LD_PRELOAD=") + SBPTT_THREAD_START_FAILS;
  const fs::path dir = fresh_directory("thread_limit");
  // --evaluate-beside starts a pool of 2 threads (one new) after the engine's.
  for (const auto& [allowed, flags] : std::vector<std::pair<int, std::string>>{
           {0, "--threads 8"}, {1, "--threads 8"}, {5, "--threads 8"},
           {0, "--threads 2 --evaluate-beside"}, {1, "--threads 2 --evaluate-beside"},
           {7, "--threads 8 --evaluate-beside"}}) {
    const auto r = sbptt::testing::run(
        "cartpole", flags + " --epochs 1 --samples 8 --csv " + (dir / "l.csv").string(),
        "SBPTT_THREADS_ALLOWED=" + std::to_string(allowed) + " " + shim + " timeout 60 ");
    INFO(allowed << " threads allowed, " << flags << "\n" << r.output);
    CHECK(r.status == 1);
    CHECK(r.output.find("cartpole: cannot start the threads of " + flags.substr(0, 11)) !=
          std::string::npos);
    CHECK(r.output.find("threads asked for (the caller's included): Resource temporarily "
                        "unavailable") != std::string::npos);
    const bool beside_failed = flags.find("beside") != std::string::npos && allowed > 0;
    CHECK((r.output.find(flags.substr(0, 11) + " and --evaluate-beside: evaluate_beside: its "
                         "thread beside the training: the system started 1 of the 2") !=
           std::string::npos) == beside_failed);
  }
  // bench's own probes beside the epochs (the round trip, the other core's lines, three copies
  // of an epoch at once) said only "Resource temporarily unavailable", and a copy that started
  // while the next did not ended its row's child in std::terminate ("child process failed
  // (status 6)"). Each refusal now names --threads and the threads it could not start. A row of
  // --threads 3 starts 7 threads, in this order: the engine's 2 workers, the evaluation beside,
  // the round trip's partner, the other core's writer, and 2 copies.
  const std::string probes = "--threads 3 (--threads 1 runs no host probes): ";
  const std::vector<std::string> refusals = {
      "--threads 3: the system started 1 of the 3 threads asked for",
      "--threads 3: the system started 2 of the 3 threads asked for",
      "--threads 3: evaluate_beside: its thread beside the training: the system started 1 of "
      "the 2 threads asked for",
      probes + "the cross-core round trip: the system started 1 of the 2 threads asked for",
      probes + "the read of another core's lines: the system started 1 of the 2 threads asked for",
      probes + "the copies of an epoch run at once: the system started 1 of the 3 threads asked "
               "for",
      probes + "the copies of an epoch run at once: the system started 2 of the 3 threads asked "
               "for"};
  for (std::size_t allowed = 0; allowed <= refusals.size(); ++allowed) {
    const auto r = sbptt::testing::run(
        "bench", "--tasks cartpole1 --scalars float --methods R --repeats 1 --threads 3",
        "SBPTT_THREADS_ALLOWED=" + std::to_string(allowed) + " " + shim + " timeout 120 ");
    INFO(allowed << " threads allowed\n" << r.output);
    CHECK(r.status == 0);
    CHECK(r.output.find("child process failed") == std::string::npos);
    const std::string row = "cartpole1      float  R ";
    if (allowed < refusals.size()) {
      CHECK(r.output.find(row + "failed: " + refusals[allowed] +
                          " (the caller's included): Resource temporarily unavailable; expected "
                          "a thread count within the process's limits") != std::string::npos);
    } else {
      CHECK(r.output.find(row + "failed") == std::string::npos);
      CHECK(r.output.find(row) != std::string::npos);
    }
  }
#endif
}

TEST_CASE("memory that runs out reading an input file is said to be that file's", "[programs]") {
  // A states file too large for `ulimit -v` was reported as "out of memory for --samples 8 …;
  // expected sizes whose data and trajectories fit in memory": sizes that were not the cause.
  if (sbptt::testing::address_sanitizer) {
    WARN("AddressSanitizer cannot start under ulimit -v: not checked");
    return;
  }
  const fs::path dir = fresh_directory("input_memory");
  const std::string limit = "ulimit -v 40000; ";  // 40 MB
  const auto started = sbptt::testing::run("cartpole", "--epochs 1 --samples 8", limit);
  INFO(started.output);
  REQUIRE(started.status == 0);  // the run itself fits
  // 1.5 million rows of 4 numbers: 48 MB as doubles.
  const fs::path states = dir / "states.csv";
  {
    std::string rows;
    for (int i = 0; i < 1'500'000; ++i) rows += "0,0,0,0\n";
    std::ofstream(states, std::ios::binary) << rows;
  }
  const auto r = sbptt::testing::run(
      "cartpole", "--epochs 1 --samples 8 --init-states " + states.string(), limit);
  INFO(r.output);
  CHECK(r.status == 1);
  CHECK(r.output.find("cartpole: --init-states: out of memory reading '" + states.string() +
                      "'") != std::string::npos);
  CHECK(r.output.find("--samples") == std::string::npos);
}

TEST_CASE("a descriptor limit too low for the outputs is refused before any work", "[programs]") {
  // Under `ulimit -n 5`, `--csv l.csv --checkpoint ck` trained an epoch and then could not write
  // its checkpoint ("Too many open files"); `--csv` alone trained every epoch and failed at the
  // log's last sync; train_own_scene, whose run_training does the check for a library's user,
  // trained its first epoch, could not write that epoch's checkpoint and stopped without its
  // parameters saved either. Each case starts at the lowest limit under which the program loads
  // at all (exit 127 below it: the loader cannot open libstdc++), which leaves it one descriptor
  // free: the descriptors the test runner leaves open count too. The limit the refusal asks for
  // is checked by runs under it and one below it. With stdin closed, its free number 0 is no use
  // to a run that opens its files above the standard streams.
  if (sbptt::testing::address_sanitizer) {
    WARN("AddressSanitizer opens files of its own at start: not checked");
    return;
  }
  const fs::path dir = fresh_directory("descriptor_limit");
  const std::string outputs = "--csv " + (dir / "l.csv").string() + " --checkpoint " +
                              (dir / "ck").string() + " --save-params " +
                              (dir / "p.txt").string();
  const std::string two_epochs = "--epochs 2 --samples 8 ";
  struct Case {
    std::string program, arguments, named;
    bool stdin_closed;
  };
  for (const Case& c : std::vector<Case>{
           {"cartpole", two_epochs + outputs, "--csv, --checkpoint and --save-params", false},
           {"cartpole", two_epochs + outputs, "--csv, --checkpoint and --save-params", true},
           {"cartpole", two_epochs + "--csv " + (dir / "l.csv").string(), "--csv", false},
           {"cartpole", two_epochs + "--checkpoint " + (dir / "ck").string(), "--checkpoint",
            false},
           {"cartpole", two_epochs + "--save-params " + (dir / "p.txt").string(),
            "--save-params", false},
           {"train_own_scene", dir.string(), "log_csv, checkpoint and save_params", false}}) {
    const auto limited = [&](int files) {
      // The redirections first: dash saves a descriptor above 9 for `exec … 2>&1`.
      return sbptt::testing::run(c.program, c.arguments,
                                 std::string("exec 2>&1") + (c.stdin_closed ? " 0<&-" : "") +
                                     "; ulimit -n " + std::to_string(files) + "; exec ",
                                 "");
    };
    const std::string refusal = c.program + ": " + c.named + ": ";
    int files = 4;
    auto refused = limited(files);
    while (refused.status == 127 && files < 64) refused = limited(++files);
    INFO("ulimit -n " << files << " " << c.program << " " << c.arguments
                      << (c.stdin_closed ? ", stdin closed" : "") << "\n"
                      << refused.output);
    CHECK(refused.status == 1);
    CHECK(refused.output.find(refusal) == 0);
    CHECK(refused.output.find("epoch") == std::string::npos);
    CHECK(fs::is_empty(dir));
    const std::string asked = "expected ulimit -n ";
    const auto at = refused.output.find(asked);
    REQUIRE(at != std::string::npos);
    const int enough = std::stoi(refused.output.substr(at + asked.size()));
    CHECK(enough > files);
    const auto below = limited(enough - 1);
    INFO("ulimit -n " << enough - 1 << "\n" << below.output);
    CHECK(below.status == 1);
    CHECK(below.output.find(refusal) == 0);
    const auto ran = limited(enough);
    INFO("ulimit -n " << enough << "\n" << ran.output);
    CHECK(ran.status == 0);
    fs::remove_all(dir);
    fs::create_directories(dir);
  }
}
