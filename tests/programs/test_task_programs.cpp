// The task programs as a user runs them: smoke runs, --dump-gradients against finite
// differences of the printed loss, bit-exact parameter round trips, bad flags, and the
// paper-setting check that C lowers the 2-pole cart-pole loss within 20 epochs (mujoco:
// test_mujoco_program.cpp).
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include <unistd.h>

#include "programs/program_runner.hpp"
#include "sbptt/nn/parameters_io.hpp"
#include "support/address_sanitizer.hpp"

namespace fs = std::filesystem;
using sbptt::testing::file_text;
using sbptt::testing::gradient_column;
using sbptt::testing::printed_loss;
using sbptt::testing::Result;
using sbptt::testing::run;
using sbptt::testing::scratch;
using sbptt::testing::without_seconds;

TEST_CASE("every task program runs one short epoch", "[programs]") {
  const fs::path log = scratch("smoke.csv");
  for (const std::string& call :
       {std::string("toy --epochs 1"), std::string("cartpole --poles 2 --epochs 1 --samples 8 --steps 5"),
        std::string("guidance --epochs 1 --samples 8 --steps 5 --method M"),
        std::string("quantum --epochs 1 --samples 8 --steps 5 --method S --float")}) {
    const std::string program = call.substr(0, call.find(' '));
    const Result r = run(program, call.substr(call.find(' ') + 1) + " --csv " + log.string());
    INFO(call << "\n" << r.output);
    CHECK(r.status == 0);
    std::ifstream in(log);
    std::string header, row;
    std::getline(in, header);
    std::getline(in, row);
    CHECK(header == "epoch,batch_loss,train_loss,test_loss,update_norm2,cos_m_r,agree_fraction,seconds");
    CHECK(row.rfind("1,", 0) == 0);
  }
}

TEST_CASE("--dump-gradients: R equals central differences of the printed batch loss",
          "[programs]") {
  // Train a few epochs so that every layer (also the zero-initialised last one) is non-zero.
  const fs::path params = scratch("guidance.params"), dump = scratch("dump.csv");
  const std::string base = "--samples 4 --steps 12 ";
  REQUIRE(run("guidance", base + "--epochs 3 --save-params " + params.string()).status == 0);
  const Result at = run("guidance", base + "--init-params " + params.string() +
                                        " --dump-gradients " + dump.string());
  REQUIRE(at.status == 0);
  const std::vector<double> regular = gradient_column(dump, 1);
  const auto theta = sbptt::load_parameters<double>(params, static_cast<sbptt::Index>(regular.size()));
  REQUIRE(regular.size() == 13004);  // 24 → 100 → 100 → 4
  const double h = 1e-6;
  // A first-layer weight, a hidden bias, a last-layer weight and the last bias.
  for (sbptt::Index p : {sbptt::Index{5}, sbptt::Index{2450}, sbptt::Index{12700}, sbptt::Index{13003}}) {
    double losses[2];
    for (int side = 0; side < 2; ++side) {
      auto shifted = theta;
      shifted(p) += side == 0 ? h : -h;
      const fs::path file = scratch("shifted.params");
      sbptt::save_parameters(file, shifted);
      const Result r = run("guidance", base + "--init-params " + file.string() +
                                           " --dump-gradients " + scratch("unused.csv").string());
      REQUIRE(r.status == 0);
      losses[side] = printed_loss(r.output);
    }
    const double fd = (losses[0] - losses[1]) / (2 * h);
    INFO("parameter " << p);
    CHECK(regular[static_cast<std::size_t>(p)] == Approx(fd).epsilon(1e-5).margin(1e-9));
  }
}

TEST_CASE("toy --dump-gradients reproduces the paper's table at θ = (2, −1)", "[programs]") {
  const fs::path params = scratch("toy.params"), dump = scratch("toy.csv");
  std::ofstream(params) << "2\n-1\n";
  const Result r = run("toy", "--init-params " + params.string() + " --dump-gradients " + dump.string());
  REQUIRE(r.status == 0);
  CHECK(printed_loss(r.output) == Approx(1.99972).epsilon(1e-5));
  CHECK(gradient_column(dump, 1)[0] == Approx(-2.11568e-3).epsilon(1e-5));  // R (vanishing)
  CHECK(gradient_column(dump, 2)[0] == Approx(-0.253321).epsilon(1e-5));    // M
  CHECK(gradient_column(dump, 3)[1] == 0.0);                                // C: signs disagree
}

TEST_CASE("--init-params then --save-params round-trips bit for bit", "[programs]") {
  const fs::path first = scratch("first.params"), second = scratch("second.params");
  REQUIRE(run("cartpole", "--epochs 1 --samples 8 --steps 10 --save-params " + first.string()).status == 0);
  REQUIRE(run("cartpole", "--epochs 0 --init-params " + first.string() + " --save-params " +
                              second.string()).status == 0);
  const std::string text = file_text(first);
  CHECK(text.size() > 10000);
  CHECK(text == file_text(second));
}

TEST_CASE("--init-params then --save-params keeps 17-digit values exactly", "[programs]") {
  // Hand-written values that need all 17 digits (thirds), and the extremes of the range: a
  // writer that rounds to fewer digits or flushes subnormals changes one of them.
  std::vector<double> values(10701);  // 1-pole cart pole: 4 → 100 → 100 → 1
  for (std::size_t i = 0; i < values.size(); ++i)
    values[i] = (i % 2 ? -1.0 : 1.0) * static_cast<double>(i + 1) / 3.0 * 1e-5;
  values[7] = 4.9406564584124654e-324;   // the smallest subnormal
  values[8] = -2.2250738585072014e-308;  // the smallest normal
  values[9] = 0.10000000000000001;       // 0.1, which %.15g would also print as 0.1
  std::string text;
  char line[64];
  for (double v : values) {
    std::snprintf(line, sizeof line, "%.17g\n", v);
    text += line;
  }
  const fs::path in = scratch("digits.params"), out = scratch("digits_out.params");
  std::ofstream(in, std::ios::binary) << text;
  const Result r = run("cartpole", "--epochs 0 --samples 8 --init-params " + in.string() +
                                       " --save-params " + out.string());
  INFO(r.output);
  REQUIRE(r.status == 0);
  CHECK(file_text(out) == text);  // the format is %.17g, so even the text is the same
  std::ifstream saved(out);
  std::string number;
  std::size_t i = 0, exact = 0;
  while (std::getline(saved, number) && i < values.size())
    exact += std::strtod(number.c_str(), nullptr) == values[i++] ? 1 : 0;
  CHECK(i == values.size());
  CHECK(exact == values.size());
}

TEST_CASE("--threads 2 trains to the same parameters, bit for bit, as one thread", "[programs]") {
  // Quantum with split_above_ns's default splits its per-sample loops, and C runs its two
  // sweeps at once: every threaded path of the engine is on. On a grid of run-time size
  // (--nx other than 32) the quantum step is a per-sample call, not the batched lanes; so
  // are double guidance's and the cart pole's.
  for (const std::string& call : {std::string("cartpole --poles 2 --method C --epochs 2 --samples 16 --steps 20"),
                                  std::string("quantum --method C --epochs 1 --samples 16 --steps 8"),
                                  std::string("quantum --nx 16 --method C --epochs 1 --samples 16 --steps 8"),
                                  std::string("guidance --method C --epochs 1 --samples 16 --steps 8")}) {
    const std::string program = call.substr(0, call.find(' '));
    const std::string arguments = call.substr(call.find(' ') + 1);
    const fs::path one = scratch(program + "_t1.params"), two = scratch(program + "_t2.params");
    const Result r1 = run(program, arguments + " --threads 1 --save-params " + one.string());
    const Result r2 = run(program, arguments + " --threads 2 --save-params " + two.string());
    INFO(call << "\n" << r1.output << r2.output);
    REQUIRE(r1.status == 0);
    REQUIRE(r2.status == 0);
    const std::string text = file_text(one);
    CHECK(text.size() > 10000);
    CHECK(text == file_text(two));
  }
}

TEST_CASE("--evaluate-beside trains and logs the same, bit for bit, as without it",
          "[programs]") {
  // Evaluated every epoch, so that each epoch but the last is evaluated beside the next one.
  const std::string arguments = "--poles 2 --method C --epochs 4 --samples 16 --steps 20";
  std::string params[2], logs[2];
  for (int beside : {0, 1}) {
    const fs::path saved = scratch("beside" + std::to_string(beside) + ".params");
    const fs::path log = scratch("beside" + std::to_string(beside) + ".csv");
    const Result r = run("cartpole", arguments + (beside ? " --evaluate-beside" : "") +
                                         " --csv " + log.string() + " --save-params " +
                                         saved.string());
    INFO(r.output);
    REQUIRE(r.status == 0);
    CHECK((r.output.find("each evaluation beside the next epoch's training") !=
           std::string::npos) == (beside == 1));
    params[beside] = file_text(saved);
    logs[beside] = without_seconds(file_text(log));
  }
  CHECK(params[0].size() > 10000);
  CHECK(params[1] == params[0]);
  CHECK(std::count(logs[0].begin(), logs[0].end(), '\n') == 5);  // the header and 4 epochs
  CHECK(logs[1] == logs[0]);
}

TEST_CASE("--physical runs the physical variants of the cart pole and guidance", "[programs]") {
  const fs::path dump = scratch("physical_dump.csv");
  auto loss = [&](const std::string& program, const std::string& arguments) {
    const Result r = run(program, arguments + " --samples 4 --dump-gradients " + dump.string());
    INFO(program << " " << arguments << "\n" << r.output);
    REQUIRE(r.status == 0);
    return printed_loss(r.output);
  };
  // One pole on a cart of mass M − m is the reference system; two poles feel each other.
  CHECK(std::abs(loss("cartpole", "--poles 1") - loss("cartpole", "--poles 1 --physical")) < 1e-12);
  CHECK(std::abs(loss("cartpole", "--poles 2") - loss("cartpole", "--poles 2 --physical")) > 1e-6);
  // Flocking as intended repels the evaders where the reference attracts them.
  CHECK(std::abs(loss("guidance", "") - loss("guidance", "--physical")) > 1e-6);
  const Result toy = run("toy", "--physical");
  CHECK(toy.status == 2);
  CHECK(toy.output.find("unknown flag '--physical'") != std::string::npos);
}

TEST_CASE("--model chain runs the n-link chain on a cart, 1 to 3 links", "[programs]") {
  const fs::path dump = scratch("chain_dump.csv");
  auto loss = [&](const std::string& arguments) {
    const Result r = run("cartpole", arguments + " --samples 4 --dump-gradients " + dump.string());
    INFO(arguments << "\n" << r.output);
    REQUIRE(r.status == 0);
    return printed_loss(r.output);
  };
  // One link is the physical one-pole cart pole; two links hinged end to end are not two poles
  // side by side.
  CHECK(std::abs(loss("--poles 1 --model chain") - loss("--poles 1 --physical")) < 1e-12);
  CHECK(std::abs(loss("--poles 2 --model chain") - loss("--poles 2 --physical")) > 1e-6);
  CHECK(std::abs(loss("--poles 1 --model physical") - loss("--poles 1 --physical")) == 0);
  CHECK(std::isfinite(loss("--poles 3 --model chain --float")));
  const Result four = run("cartpole", "--poles 4 --model chain");
  CHECK(four.status == 2);
  CHECK(four.output.find("--poles 4 with --model chain; expected 1 to 3 links") != std::string::npos);
  const Result unknown = run("cartpole", "--model ladder");
  CHECK(unknown.status == 2);
  CHECK(unknown.output.find("--model 'ladder' is unknown") != std::string::npos);
}

TEST_CASE("bad flags get exit code 2 and a message naming the value", "[programs]") {
  struct Case {
    std::string program, arguments, expected;
  };
  for (const Case& c : {Case{"cartpole", "--poles 0", "--poles 0 is out of range"},
                        Case{"cartpole", "--poles 99", "--poles 99 is out of range"},
                        Case{"cartpole", "--batch 0", "--batch 0 is out of range"},
                        Case{"cartpole", "--steps -1", "--steps -1 is out of range"},
                        Case{"guidance", "--dt 0", "--dt 0 is out of range"},
                        Case{"quantum", "--lr nan", "--lr nan is out of range"},
                        Case{"quantum", "--epochs ten", "--epochs 'ten' is not an integer"},
                        Case{"toy", "--frobnicate", "unknown flag '--frobnicate'"},
                        Case{"toy", "--poles 2", "unknown flag '--poles'"},
                        Case{"guidance", "--rc", "--rc needs a value"},
                        Case{"cartpole", "--method X", "--method: method 'X' is unknown"},
                        Case{"cartpole", "--clip Norm", "--clip: clip mode \"Norm\" is not recognised"},
                        // A dt or T derived from the others keeps to its own flag's range.
                        Case{"cartpole", "--steps 3 --T 1e-12",
                             "--steps 3 with --T 1e-12: dt = 3.33333333333333e-13 is out of range; "
                             "expected dt in [1e-12, 1000000]"},
                        Case{"cartpole", "--steps 1 --T 1e9 --epochs 1 --samples 2",
                             "--steps 1 with --T 1000000000: dt = 1000000000 is out of range"},
                        Case{"cartpole", "--steps 1000000 --dt 1e6 --epochs 0 --samples 1",
                             "--steps 1000000 with --dt 1000000: T = 1000000000000 is out of range; "
                             "expected T in [1e-12, 1000000000]"},
                        Case{"cartpole", "--samples 1000000000", "--samples 1000000000 is out of range"},
                        Case{"guidance", "--steps 1000001", "--steps 1000001 is out of range"},
                        Case{"cartpole", "--T 1e9", "expected at most 1000000 steps"},
                        Case{"quantum", "--epochs 10000000", "--epochs 10000000 is out of range"},
                        Case{"toy", "--dt 0.5", "--dt: the toy system x' = x + c is a map with no time step"},
                        Case{"toy", "--T 4", "--T: the toy system"},
                        Case{"cartpole", "--nx 64", "unknown flag '--nx'"}}) {
    const Result r = run(c.program, c.arguments);
    INFO(c.program << " " << c.arguments << "\n" << r.output);
    CHECK(r.status == 2);
    CHECK(r.output.find(c.expected) != std::string::npos);
    CHECK(r.output.find("initial test loss") == std::string::npos);
  }
}

TEST_CASE("unreadable inputs and unwritable outputs fail at once with exit 1", "[programs]") {
  // Every message names the flag whose file failed (the inputs' named only the file).
  struct Case {
    std::string arguments, expected;
  };
  std::ofstream(scratch("narrow.csv")) << "1,2\n";
  for (const Case& c :
       {Case{"--init-params /nonexistent/p.txt", "cannot open '/nonexistent/p.txt'"},
        Case{"--init-params " + scratch("").string(), "is a directory"},
        Case{"--init-states /nonexistent/s.csv", "load_states: cannot open '/nonexistent/s.csv' for reading"},
        Case{"--init-states " + scratch("").string(), "is a directory"},
        Case{"--init-states " + scratch("narrow.csv").string(), "2 columns; expected exactly state_dim = 4"},
        Case{"--csv /nonexistent/dir/log.csv", "directory '/nonexistent/dir' does not exist"},
        Case{"--save-params " + (scratch("narrow.csv") / "p.txt").string(), "is not a directory"},
        // A directory passes the parent's checks; it must fail now, not at the final rename.
        Case{"--csv " + scratch("").string(), "exists and is not a regular file (a directory)"},
        Case{"--save-params " + scratch("").string(), "exists and is not a regular file"}}) {
    const Result r = run("cartpole", "--epochs 1 --samples 8 --steps 3 " + c.arguments);
    INFO(c.arguments << "\n" << r.output);
    CHECK(r.status == 1);
    CHECK(r.output.find(c.expected) != std::string::npos);
    CHECK(r.output.find(c.arguments.substr(0, c.arguments.find(' '))) != std::string::npos);
    CHECK(r.output.find("epoch 1") == std::string::npos);  // failed before training
  }
}

TEST_CASE("a parameters or states file without newlines is refused at once", "[programs]") {
  // /dev/zero never ends: a reader without a bound would fill the memory (capped here, so that
  // a regression fails instead of taking the machine down).
  const std::string cap = sbptt::testing::address_sanitizer ? "" : "ulimit -v 4000000; ";
  for (const auto& [flag, expected] :
       {std::pair<std::string, std::string>{"--init-params", "line 1: longer than 64 characters"},
        {"--init-states", "line 1: longer than 260 characters"}}) {
    const Result r = run("cartpole", "--epochs 1 --samples 8 --steps 3 " + flag + " /dev/zero", cap);
    INFO(flag << "\n" << r.output);
    CHECK(r.status == 1);
    CHECK(r.output.find(expected) != std::string::npos);
    CHECK(r.output.find("\\x00\\x00") != std::string::npos);  // shown escaped, not raw
    CHECK(r.output.find('\0') == std::string::npos);
  }
}

TEST_CASE("running out of memory names the sizes asked for", "[programs]") {
  // Under ASan the programs cannot even start in 2 GB of address space (its shadow memory).
  if (sbptt::testing::address_sanitizer) return;
  // The budget's lower bound (memory_budget.hpp), 824.3 MB at --nx 1024 (a trajectory of 129
  // × 8 samples × 99,023 doubles and the sets' 16 × 98,999), passes under 829.4 MB of address
  // space; the program beside it does not (it runs under 839.7 MB).
  const Result r = run("quantum", "--samples 8 --batch 8 --nx 1024 --epochs 1",
                       "ulimit -v 810000; ");
  INFO(r.output);
  CHECK(r.status == 1);
  CHECK(r.output.find("out of memory for --samples 8") != std::string::npos);
  CHECK(r.output.find("--nx 1024") != std::string::npos);
}

TEST_CASE("sizes that cannot fit in memory are refused before any work", "[programs]") {
  if (sbptt::testing::address_sanitizer) return;
  const fs::path log = scratch("too_big.csv");
  fs::remove(log);
  // Under a 2 GB address-space limit. The sets: 1e6 samples × (4 × 2048 states, generated and
  // split, + 96,975 of the network's record at --nx 1024 for their evaluation) × 8 bytes; a
  // trajectory: 129 × 8 × (2048 + 96,975) × 8 bytes = 0.8 GiB.
  Result r = run("quantum", "--samples 1000000 --nx 1024 --epochs 1 --csv " + log.string(),
                 "ulimit -v 2000000; ");
  INFO(r.output);
  CHECK(r.status == 2);
  CHECK(r.output.find("--samples 1000000 (and as many test samples) with --nx 1024, --batch 8 "
                      "and --steps 128 need at least") != std::string::npos);
  CHECK(r.output.find("GiB for the sets and their evaluation, 0.8 GiB for a batch's "
                      "trajectory)") != std::string::npos);
  CHECK(r.output.find("more than the 1.9 GiB this process may use (ulimit -v)") !=
        std::string::npos);
  CHECK_FALSE(fs::exists(log));
  // A need and a bound within 0.05 GiB were both "0.8 GiB": "need at least 0.8 GiB …, more
  // than the 0.8 GiB this process may use". 800,000 KiB is 0.763 GiB; the need, 0.77 GiB.
  r = run("quantum", "--samples 8 --nx 1024 --epochs 1", "ulimit -v 800000; ");
  INFO(r.output);
  CHECK(r.status == 2);
  CHECK(r.output.find("need at least 0.77 GiB") != std::string::npos);
  CHECK(r.output.find("more than the 0.76 GiB this process may use") != std::string::npos);
  // The trajectory alone: 256 samples a batch need 24.4 GiB.
  r = run("quantum", "--samples 256 --batch 256 --nx 1024 --epochs 1", "ulimit -v 2000000; ");
  INFO(r.output);
  CHECK(r.status == 2);
  CHECK(r.output.find("24.4 GiB for a batch's trajectory") != std::string::npos);
  // The flags that set a state's size are named as --nx is: they were left out.
  for (const auto& [program, flags] :
       {std::pair<std::string, std::string>{"guidance", "--drivers 16 --evaders 64"},
        {"cartpole", "--poles 4 --batch 1000000"}}) {
    r = run(program, "--samples 1000000 --epochs 1 " + flags, "ulimit -v 2000000; ");
    INFO(r.output);
    CHECK(r.status == 2);
    const std::string named = program == "guidance" ? "with --drivers 16 and --evaders 64, "
                                                    : "with --poles 4, ";
    CHECK(r.output.find("--samples 1000000 (and as many test samples) " + named) !=
          std::string::npos);
  }
  // With no limit set: sizes beyond the machine's memory are refused too, not left to the
  // kernel's out-of-memory killer. The largest sizes the flags allow generate 131 GB at once;
  // on a machine with less than that (so that the old code failed at once too).
  const double memory = static_cast<double>(sysconf(_SC_PHYS_PAGES)) *
                        static_cast<double>(sysconf(_SC_PAGE_SIZE));
  if (memory >= 2e6 * 8192 * 8) return;
  r = run("quantum", "--samples 1000000 --nx 4096 --epochs 1");
  INFO(r.output);
  CHECK(r.status == 2);
  CHECK(r.output.find("this process may use (physical memory)") != std::string::npos);
}

TEST_CASE("a cgroup's memory limit above the program's own cgroup is honoured", "[programs]") {
  // Slurm limits a job's cgroup and runs its task in a cgroup below it, whose own limit is
  // "max". The kernel killed such a run (SIGKILL, no message) once its pages outgrew the job's
  // limit. Here: 1e9 bytes on a parent cgroup, the program in a child; its 1.5 GiB trajectory
  // (quantum --nx 1024, batch 16) cannot fit. Needs root and a writable memory cgroup (v1 or v2).
  if (sbptt::testing::address_sanitizer) return;
  // Below this process's own cgroup, so that the program stays within its container's or job's.
  const bool v1 = fs::exists("/sys/fs/cgroup/memory/cgroup.procs");
  std::string own;
  std::ifstream cgroups("/proc/self/cgroup");
  for (std::string line; std::getline(cgroups, line);) {
    const auto memory = line.find(":memory:");
    if (v1 && memory != std::string::npos) own = line.substr(memory + 8);
    if (!v1 && line.rfind("0::", 0) == 0) own = line.substr(3);
  }
  const fs::path parent = fs::path(v1 ? "/sys/fs/cgroup/memory" : "/sys/fs/cgroup") /
                          fs::path(own).relative_path() /
                          ("sbptt_test_" + std::to_string(getpid()));
  const std::string limit_file = v1 ? "memory.limit_in_bytes" : "memory.max";
  std::error_code error;
  fs::create_directories(parent / "inner", error);
  if (error || !fs::exists(parent / limit_file) ||
      !(std::ofstream(parent / limit_file) << "1000000000\n")) {
    fs::remove(parent / "inner", error);
    fs::remove(parent, error);
    WARN("no writable memory cgroup (not root, or no memory controller): skipped");
    return;
  }
  const Result r = run("quantum", "--samples 16 --batch 16 --nx 1024 --epochs 1",
                       "echo $$ > " + (parent / "inner" / "cgroup.procs").string() + " && ");
  fs::remove(parent / "inner", error);
  fs::remove(parent, error);
  INFO(r.output);
  CHECK(r.status == 2);
  CHECK(r.output.find("1.5 GiB for a batch's trajectory), more than the 0.9 GiB this process "
                      "may use (the memory limit of its cgroup)") != std::string::npos);
}

TEST_CASE("skip-batch reports each skipped batch and never ends silently on NaN",
          "[programs]") {
  // lr 1e6 makes the first update overflow the next batch and then the evaluation. Adam's first
  // step is ±lr in every component, so the sign of the overflow follows the signs of gradient
  // components near zero, i.e. the rounding of the build: either infinity is right.
  const fs::path params = scratch("skip.params"), log = scratch("skip.csv");
  fs::remove(log);
  const Result r = run("cartpole", "--epochs 3 --samples 16 --method R --lr 1e6 "
                                   "--on-nonfinite skip-batch --csv " + log.string() +
                                   " --save-params " + params.string());
  INFO(r.output);
  CHECK(r.status == 3);
  // Sample 8: the train set's column, the first of batch 1 (batches of 8, not shuffled).
  CHECK(std::regex_search(r.output, std::regex(R"(non-finite state \(-?inf\) in epoch 1, )"
                                               R"(batch 1, step 9, sample 8; batch skipped)")));
  CHECK(r.output.find("training stopped in epoch 1") != std::string::npos);
  CHECK(r.output.find("final test loss") == std::string::npos);
  CHECK(file_text(log).find("nan") == std::string::npos);
  CHECK(sbptt::load_parameters<double>(params, 10701).allFinite());  // load rejects NaN/Inf
}

TEST_CASE("a stop names the kept epoch as evaluated only if its log row has losses",
          "[programs]") {
  // With --evaluate-every > 1 the epoch before the stop may have been trained and not
  // evaluated; the message called it "the last whose evaluation was finite" all the same.
  // One batch an epoch at lr 1e6: epoch 1's update is finite, epoch 2's rollout overflows, in
  // every build (a chaotic blow-up at lr 30 did not happen in the sanitizers' build).
  const fs::path log = scratch("kept.csv");
  fs::remove(log);
  const Result r = run("cartpole", "--epochs 3 --samples 8 --method R --lr 1e6 --evaluate-every "
                                   "1000 --on-nonfinite stop --csv " + log.string());
  INFO(r.output);
  REQUIRE(r.status == 3);
  CHECK(r.output.find("training stopped in epoch 2") != std::string::npos);
  // The log's last row is epoch 1's, and its empty train_loss says it was not evaluated.
  const std::string rows = file_text(log);
  const std::string last_row = rows.substr(rows.rfind('\n', rows.size() - 2) + 1);
  CHECK(last_row.rfind("1,", 0) == 0);
  CHECK(last_row.find(",,,") != std::string::npos);  // epoch,batch_loss,,,update_norm2,...
  CHECK(r.output.find("keeping the parameters of epoch 1, the last trained (not evaluated: "
                      "--evaluate-every 1000)") != std::string::npos);
}

TEST_CASE("a non-finite evaluation stops training at that epoch", "[programs]") {
  // One batch per epoch: the update is finite, the evaluation after it is not (of either sign,
  // as above).
  const fs::path log = scratch("evaluation.csv");
  fs::remove(log);
  const Result r = run("cartpole", "--epochs 3 --samples 8 --method R --lr 1e6 --csv " +
                                       log.string());
  INFO(r.output);
  CHECK(r.status == 3);
  CHECK(std::regex_search(r.output, std::regex(R"(non-finite state \(-?inf\) in the train-set )"
                                               R"(evaluation of epoch 1, step 9, sample 0)")));
  CHECK(r.output.find("keeping the parameters it started from") != std::string::npos);
  CHECK(r.output.find("epoch 2") == std::string::npos);
  CHECK(file_text(log).find("nan") == std::string::npos);
}

TEST_CASE("an overflow stops training with a message and finite saved parameters",
          "[programs]") {
  for (const std::string method : {"R", "C"}) {
    const fs::path params = scratch("overflow.params");
    const Result r = run("cartpole", "--poles 2 --method " + method +
                                         " --lr 1e200 --epochs 3 --samples 16 --save-params " +
                                         params.string());
    INFO(r.output);
    CHECK(r.status == 3);
    CHECK(r.output.find("non-finite state") != std::string::npos);
    CHECK(r.output.find("epoch 1, batch 1") != std::string::npos);
    CHECK(sbptt::load_parameters<double>(params, 10901).allFinite());  // load rejects NaN/Inf
  }
}

TEST_CASE("combined update, paper settings: 2-pole cart pole from ~1.9 to below 1.0 in 20 epochs, "
          "and below R", "[programs]") {
  // Test losses of the first and last logged epochs of a 20-epoch run of `method`.
  auto first_and_last = [](const std::string& method) {
    const fs::path log = scratch("cartpole20_" + method + ".csv");
    const Result r = run("cartpole", "--poles 2 --method " + method + " --epochs 20 --csv " +
                                         log.string());
    INFO(r.output);
    REQUIRE(r.status == 0);
    std::ifstream in(log);
    std::string line, first, last;
    std::getline(in, line);
    std::getline(in, first);
    last = first;
    while (std::getline(in, line)) last = line;
    auto test_loss = [](const std::string& row) {
      std::stringstream fields(row);
      std::string field;
      for (int i = 0; i < 4; ++i) std::getline(fields, field, ',');
      return std::stod(field);
    };
    return std::pair{test_loss(first), test_loss(last)};
  };
  const auto [c_first, c_last] = first_and_last("C");
  CHECK(c_first > 1.5);
  CHECK(c_last < 1.0);
  // Below 1.0 alone does not single out C (R ends near 0.9, M near 0.76, C near 0.48).
  const auto r_last = first_and_last("R").second;
  CHECK(c_last < r_last);
}

TEST_CASE("a checkpoint of another cart pole model is refused, naming the flag", "[programs]") {
  // Each pair differs only in the model: resumed, the second run would continue the first
  // one's training on other physics (mujoco's --model and --target: the test above).
  struct Case {
    std::string program, first, second, expected;
  };
  int n = 0;
  for (const Case& c :
       {Case{"cartpole", "--poles 2 --model chain", "--poles 2",
             "was made with --model = chain; this run has --model = reference"},
        Case{"cartpole", "--physical", "", "was made with --model = physical; this run has "
                                           "--model = reference"},
        // The last --model given wins (it recorded chain here, and resumed).
        Case{"cartpole", "--poles 2 --model chain", "--poles 2 --model chain --model reference",
             "was made with --model = chain; this run has --model = reference"}}) {
    const fs::path file = scratch("identity" + std::to_string(++n) + ".checkpoint");
    fs::remove(file);
    const std::string checkpoint = " --samples 4 --steps 5 --checkpoint " + file.string();
    const Result first = run(c.program, c.first + checkpoint + " --epochs 2");
    INFO(c.program << " " << c.first << " | " << c.second << "\n" << first.output);
    REQUIRE(first.status == 0);
    const Result second = run(c.program, c.second + checkpoint + " --epochs 4");
    INFO(second.output);
    CHECK(second.status == 2);
    CHECK(second.output.find(c.expected) != std::string::npos);
    CHECK(second.output.find("resuming") == std::string::npos);
  }
}
