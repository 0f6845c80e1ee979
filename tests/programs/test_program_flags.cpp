// The command lines of the example programs as a user meets them: --help of every program, the
// time-stepping rules of docs/programs.md, the real ranges, and flags that would be ignored.
#include <catch2/catch.hpp>

#include <csignal>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "programs/program_runner.hpp"
#include "sbptt/core/instruction_set.hpp"
#include "support/address_sanitizer.hpp"
#include "support/files.hpp"

namespace fs = std::filesystem;
using sbptt::testing::printed_loss;
using sbptt::testing::Result;
using sbptt::testing::run;
using sbptt::testing::scratch;

namespace {

/// The line of `help` that documents `flag` ("  --flag ..."), or "" if none.
std::string help_line(const std::string& help, const std::string& flag) {
  std::istringstream lines(help);
  std::string line, documented;
  while (std::getline(lines, line)) {
    if (line.rfind("  " + flag + " ", 0) == 0 || line.rfind("  " + flag + "=", 0) == 0 ||
        line == "  " + flag) {
      documented = line;
      // A long flag column pushes the meaning onto the next line.
      if (std::getline(lines, line) && line.rfind("  --", 0) != 0) documented += line;
      return documented;
    }
  }
  return "";
}

/// The header line a task program prints first on stderr.
std::string header(const Result& r) { return r.output.substr(0, r.output.find('\n')); }

}  // namespace

TEST_CASE("--help of every program lists each flag with its meaning, default and range",
          "[programs]") {
  struct Flag {
    std::string name;
    bool valued;   // takes a value, so --help shows its default
    bool ranged;   // a number, so --help shows its range
  };
  const std::vector<Flag> common = {
      {"--method", true, false},        {"--clip", true, false},
      {"--clip-threshold", true, true}, {"--epochs", true, true},
      {"--batch", true, true},          {"--samples", true, true},
      {"--lr", true, true},             {"--seed", true, true},
      {"--shuffle", false, false},      {"--truncation", true, true},
      {"--on-nonfinite", true, false},  {"--steps", true, true},
      {"--float", false, false},        {"--double", false, false},
      {"--threads", true, true},        {"--csv", true, false},
      {"--save-params", true, false},   {"--init-params", true, false},
      {"--init-states", true, false},   {"--dump-gradients", true, false},
      {"--evaluate-beside", false, false}};
  const std::vector<Flag> timed = {{"--dt", true, true}, {"--T", true, true}};
  struct Program {
    std::string name;
    std::vector<std::vector<Flag>> flags;
  };
  const std::vector<Program> programs = {
      {"toy", {common}},
      {"cartpole", {common, timed, {{"--poles", true, true}, {"--physical", false, false}}}},
      {"guidance",
       {common, timed,
        {{"--drivers", true, true}, {"--evaders", true, true}, {"--rc", true, true},
         {"--physical", false, false}}}},
      {"quantum", {common, timed, {{"--target", true, true}, {"--nx", true, true}}}},
      {"bench",
       {{{"--csv", true, false}, {"--repeats", true, true}, {"--threads", true, true},
         {"--sweep-threading", true, false}, {"--tasks", true, false}, {"--scalars", true, false},
         {"--methods", true, false}}}},
      {"accuracy", {{{"--csv", true, false}}}},
      {"rotation",
       {{{"--k", true, true}, {"--lr", true, true}, {"--iterations", true, true},
         {"--csv", true, false}}}},
      {"reproduce",
       {{{"--profile", true, false}, {"--tasks", true, false}, {"--methods", true, false},
         {"--clips", true, false}, {"--complexities", true, true}, {"--seeds", true, true},
         {"--epochs", true, true}, {"--samples", true, true}, {"--float", false, false},
         {"--jobs", true, true}, {"--threads", true, true}, {"--out", true, false},
         {"--bin-dir", true, false}, {"--dry-run", false, false}, {"--emit", true, false},
         {"--shard", true, false}, {"--run", true, false}, {"--merge", false, false},
         {"--no-plot", false, false}, {"--python", true, false},
         {"--plot-script", true, false}}}}};
  for (const Program& program : programs) {
    const Result r = run(program.name, "--help");
    INFO(program.name << " --help\n" << r.output);
    REQUIRE(r.status == 0);
    for (const auto& group : program.flags) {
      for (const Flag& flag : group) {
        const std::string line = help_line(r.output, flag.name);
        INFO(flag.name << ": " << line);
        REQUIRE(!line.empty());
        // A meaning: words after the flag and its value column.
        CHECK(line.find_first_of("abcdefghijklmnopqrstuvwxyz", line.find("  ", flag.name.size() + 2)) !=
              std::string::npos);
        if (flag.valued) CHECK(line.find(flag.name + " ") != std::string::npos);
        if (flag.valued) CHECK(line.find('=') != std::string::npos);  // "--epochs N=1000"
        if (flag.ranged) CHECK(line.find(" in [") != std::string::npos);
      }
    }
  }
}

TEST_CASE("--dt alone keeps T and adapts the steps; the header prints steps, dt and T",
          "[programs]") {
  struct Case {
    std::string program, arguments, expected;
  };
  // T = steps · dt: the cart pole's T = 1 s, guidance's 4 s and quantum's 8 are the paper's.
  for (const Case& c :
       {Case{"cartpole", "--dt 0.02", "50 steps of dt 0.02, T 1,"},
        Case{"cartpole", "--dt 0.005", "200 steps of dt 0.005, T 1,"},
        Case{"cartpole", "--steps 50", "50 steps of dt 0.01, T 0.5,"},
        Case{"cartpole", "--T 2", "200 steps of dt 0.01, T 2,"},
        Case{"cartpole", "--steps 50 --T 2", "50 steps of dt 0.04, T 2,"},
        Case{"cartpole", "", "100 steps of dt 0.01, T 1,"},
        Case{"guidance", "--dt 0.1", "40 steps of dt 0.1, T 4,"},
        Case{"guidance", "", "60 steps of dt 0.0666666666666667, T 4,"},
        Case{"quantum", "--dt 0.125", "64 steps of dt 0.125, T 8,"},
        Case{"quantum", "--T 4", "64 steps of dt 0.0625, T 4,"},
        Case{"toy", "--steps 6", "6 steps (a map, no dt)"}}) {
    const Result r = run(c.program, c.arguments + " --epochs 0 --samples 2");
    INFO(c.program << " " << c.arguments << "\n" << r.output);
    CHECK(r.status == 0);
    CHECK(header(r).find(c.expected) != std::string::npos);
  }
  // The run really uses them: --dt 0.02 alone is the same simulation as --steps 50 --T 1.
  const fs::path dump = scratch("dt_dump.csv");
  const Result by_dt = run("cartpole", "--dt 0.02 --samples 4 --dump-gradients " + dump.string());
  const Result by_steps =
      run("cartpole", "--steps 50 --T 1 --samples 4 --dump-gradients " + dump.string());
  const Result paper = run("cartpole", "--samples 4 --dump-gradients " + dump.string());
  INFO(by_dt.output << by_steps.output << paper.output);
  REQUIRE(by_dt.status == 0);
  REQUIRE(by_steps.status == 0);
  CHECK(printed_loss(by_dt.output) == printed_loss(by_steps.output));
  CHECK(printed_loss(by_dt.output) != printed_loss(paper.output));
}

TEST_CASE("a dt that does not divide T is a bad flag, for every timed task", "[programs]") {
  for (const std::string program : {"cartpole", "guidance", "quantum"}) {
    const Result r = run(program, "--dt 0.03 --epochs 0");
    INFO(program << "\n" << r.output);
    CHECK(r.status == 2);
    CHECK(r.output.find("--dt 0.03: T = ") != std::string::npos);
    CHECK(r.output.find("is not a whole number of steps of dt = 0.03") != std::string::npos);
  }
}

TEST_CASE("quantum --nx: the range --help states is the range that runs", "[programs]") {
  // The CNN's first conv (k3, s2) gives (nx − 3)/2 + 1 points and the second needs 3 of them,
  // so nx = 7 is the smallest grid: 6 is refused where the flag is read, 7 trains.
  const Result six = run("quantum", "--nx 6 --epochs 1 --samples 2 --steps 2");
  INFO(six.output);
  CHECK(six.status == 2);
  CHECK(six.output.find("--nx 6 is out of range; expected an integer in [7, 4096]") !=
        std::string::npos);
  const Result seven = run("quantum", "--nx 7 --epochs 1 --samples 2 --steps 2");
  INFO(seven.output);
  CHECK(seven.status == 0);
  CHECK(seven.output.find("final test loss") != std::string::npos);
}

TEST_CASE("--dump-gradients of a blown-up state reports it, exits 3 and writes nothing",
          "[programs]") {
  // θ = (1e200, 0): x₁ = −0.3 + 1e200 · 0.09 and its square overflows in the next control.
  const fs::path params = scratch("huge.params"), dump = scratch("huge_dump.csv");
  std::ofstream(params) << "1e200\n0\n";
  fs::remove(dump);
  const Result r = run("toy", "--init-params " + params.string() + " --dump-gradients " +
                                  dump.string());
  INFO(r.output);
  CHECK(r.status == 3);
  CHECK(r.output.find("--dump-gradients: non-finite control (inf) in the forward pass, step 1, "
                      "sample 0; no gradients written") != std::string::npos);
  CHECK(r.output.find("loss=") == std::string::npos);
  CHECK(!fs::exists(dump));
}

TEST_CASE("--help of the task programs lists every exit code they can end with",
          "[programs]") {
  for (const std::string program : {"toy", "cartpole", "guidance", "quantum", "mujoco"}) {
    const Result r = run(program, "--help");
    INFO(program << " --help\n" << r.output);
    REQUIRE(r.status == 0);
    const std::string signals = "128 + the signal (" + std::to_string(128 + SIGINT) + ", " +
                                std::to_string(128 + SIGTERM) + ", " +
                                std::to_string(128 + SIGHUP) + ", " +
                                std::to_string(128 + SIGXCPU) +
                                ") after SIGINT, SIGTERM, SIGHUP or SIGXCPU";
    for (const std::string& code :
         {std::string("0 success"), std::string("1 error"), std::string("2 bad flag"),
          std::string("3 a non-finite value"), signals})
      CHECK(r.output.find(code) != std::string::npos);
  }
}

TEST_CASE("--dump-gradients refuses the flags of training instead of ignoring them",
          "[programs]") {
  const std::string dump = "--dump-gradients " + scratch("refused.csv").string();
  for (const std::string& flag : {std::string("--epochs 5"), "--csv " + scratch("refused_log.csv").string(),
                                 "--save-params " + scratch("refused.params").string(),
                                 std::string("--lr 0.1"), std::string("--method R"),
                                 std::string("--evaluate-beside"), std::string("--threads 2")}) {
    const Result r = run("toy", dump + " " + flag);
    INFO(flag << "\n" << r.output);
    CHECK(r.status == 2);
    CHECK(r.output.find("--dump-gradients evaluates the parameters without training, so " +
                        flag.substr(0, flag.find(' '))) != std::string::npos);
  }
}

TEST_CASE("numbers beyond the type's range, numbers not in decimals, contradicting switches and "
          "switches with a value are refused, naming the flag", "[programs]") {
  struct Case {
    std::string program, arguments, expected;
  };
  for (const Case& c :
       {Case{"toy", "--epochs 99999999999999999999",
             "--epochs 99999999999999999999 is out of range; expected an integer in [0, 1000000]"},
        Case{"toy", "--lr 1e999", "--lr 1e999 is out of range; expected a finite number in "
                                  "[1e-300, 1e+300]"},
        // 1e300 is a double, but with --float it would become inf inside Adam.
        Case{"cartpole", "--float --lr 1e300", "--lr 1e+300 does not fit --float"},
        Case{"cartpole", "--float --clip norm --clip-threshold 1e-60",
             "--clip-threshold 1e-60 does not fit --float"},
        // With --clip none it was taken, though its double range is checked there too.
        Case{"cartpole", "--float --clip-threshold 1e39 --epochs 1",
             "--clip-threshold 1e+39 does not fit --float"},
        Case{"rotation", "--k", "--k needs a value"},
        Case{"bench", "--repeats 0", "--repeats 0 is out of range; expected an integer in [1, 100]"},
        Case{"bench", "--sweep-threading on",
             "--sweep-threading: sweep threading \"on\" is not recognised; expected one of timed, "
             "always, never"},
        Case{"accuracy", "--frobnicate", "unknown flag '--frobnicate'; accepted flags: --csv"},
        // Decimal numbers only, as in every file the programs read: strtod took 0x10 for 16.
        Case{"toy", "--lr 0x10", "--lr '0x10' is not a number; expected a number in [1e-300, "
                                 "1e+300]"},
        Case{"toy", "--lr=' 1e-3'", "--lr ' 1e-3' is not a number"},
        Case{"cartpole", "--double --float --epochs 1", "--float and --double both given"},
        // CLI11 read "=0" as "off" and "=foo" as "Could not convert"; a switch takes no value.
        Case{"cartpole", "--evaluate-beside=0 --epochs 1",
             "--evaluate-beside=0: --evaluate-beside is a switch and takes no value; expected "
             "--evaluate-beside alone"},
        Case{"cartpole", "--shuffle=foo --epochs 1", "--shuffle=foo: --shuffle is a switch"},
        Case{"reproduce", "--dry-run=1", "--dry-run=1: --dry-run is a switch"},
        // --help=0 printed the help and exited 0, as if the value meant something.
        Case{"cartpole", "--help=0", "--help=0: --help is a switch and takes no value; expected "
                                     "--help alone"},
        Case{"reproduce", "--help=no", "--help=no: --help is a switch"},
        // An unknown flag or a stray word beside --help printed the help and exited 0, while a
        // bad value beside it was refused.
        Case{"cartpole", "--bogus --help", "unknown flag '--bogus'; accepted flags: "},
        Case{"reproduce", "--help stray", "unexpected argument 'stray'; expected a flag"},
        // A list item's error named the flag twice ("--complexities: --complexities nan").
        Case{"reproduce", "--complexities 1,nan", "reproduce: --complexities nan is out of range"},
        // The --model callback ran after --physical's whatever the order given and reset it:
        // both ran the model of --model, --physical silently dropped.
        Case{"cartpole", "--physical --model reference --epochs 1",
             "--model reference and --physical both given"},
        Case{"cartpole", "--model chain --physical --poles 2 --epochs 1",
             "--model chain and --physical both given"},
        // A flag without its value took the next flag as the value: a log named '--float'
        // and a run in double; reproduce ran a whole sweep into './--dry-run'.
        Case{"cartpole", "--csv --float --epochs 1",
             "--csv needs a value; the next word, '--float', is a flag (a value that starts "
             "with -- is written --csv=VALUE)"},
        Case{"reproduce", "--out --dry-run", "--out needs a value; the next word, '--dry-run'"},
        Case{"toy", "--lr --epochs 1", "--lr needs a value; the next word, '--epochs'"},
        // "--flag=" with nothing after '=' (an unset shell variable) did the same: the next
        // word was taken as its value, whatever it was.
        Case{"cartpole", "--save-params= --float --epochs 1",
             "--save-params needs a value; '--save-params=' gives none (expected "
             "--save-params=VALUE or --save-params VALUE)"},
        Case{"cartpole", "--epochs= --samples 4", "--epochs needs a value; '--epochs=' gives none"},
        Case{"cartpole", "--csv= --help", "--csv needs a value; '--csv=' gives none"},
        Case{"reproduce", "--out= --dry-run", "--out needs a value; '--out=' gives none"},
        Case{"rotation", "--k=", "--k needs a value; '--k=' gives none"},
        // A value that starts with one '-' is still a value, for its own check.
        Case{"mujoco", "--model x.xml --target -1e7", "--target '-1e7': item 1, '-1e7', is not a "
                                                      "number in [-1000000, 1000000]"},
        // A flag given twice takes its last value, but an earlier bad one was never read.
        Case{"toy", "--epochs abc --epochs 1", "--epochs 'abc' is not an integer"},
        Case{"cartpole", "--method X --method C --epochs 1", "--method: method 'X' is unknown"},
        Case{"reproduce", "--seeds 0 --seeds 1 --dry-run", "--seeds 0 is out of range"},
        // "the selection leaves no run of profile quick" named no flag.
        Case{"reproduce", "--tasks chain --dry-run",
             "--profile quick has no run of the --tasks, --methods, --clips and --complexities "
             "given"}}) {
    const Result r = run(c.program, c.arguments);
    INFO(c.program << " " << c.arguments << "\n" << r.output);
    CHECK(r.status == 2);
    CHECK(r.output.find(c.expected) != std::string::npos);
  }
}

TEST_CASE("integer flags take one leading '+', as the numbers do", "[programs]") {
  const Result plus = run("toy", "--epochs +3 --batch +1");
  INFO(plus.output);
  CHECK(plus.status == 0);
  CHECK(plus.output.find(", 3 epochs,") != std::string::npos);
  for (const std::string text : {"++3", "+-3", "+"}) {
    const Result r = run("toy", "--epochs " + text);
    INFO(text << "\n" << r.output);
    CHECK(r.status == 2);
    CHECK(r.output.find("--epochs '" + text + "' is not an integer") != std::string::npos);
  }
}

TEST_CASE("bench and accuracy check --csv before measuring and name the user's path",
          "[programs]") {
  for (const std::string program : {"bench", "accuracy"}) {
    const Result r = run(program, "--csv /nonexistent/sbptt/x.csv");
    INFO(program << "\n" << r.output);
    CHECK(r.status == 1);
    CHECK(r.output.find("--csv '/nonexistent/sbptt/x.csv': directory '/nonexistent/sbptt' does "
                        "not exist") != std::string::npos);
    CHECK(r.output.find("cartpole") == std::string::npos);  // no row was measured
  }
}

TEST_CASE("the task programs check their file flags before the sets are drawn", "[programs]") {
  // quantum --samples 20000 --nx 1024 drew its sets for 1.8 s (645 MB) before it refused a --csv
  // in a missing folder. Sets that do not fit the 4 GB of `ulimit -v` show the order without
  // the wait, on any machine: the memory bound comes with drawing the sets. (AddressSanitizer
  // reserves terabytes of shadow memory at start: under a ulimit -v it cannot start at all.)
  if (sbptt::testing::address_sanitizer) {
    WARN("AddressSanitizer cannot start under ulimit -v: the order of the checks is not seen");
  } else {
    const Result r = run("quantum", "--samples 20000 --nx 1024 --csv /nonexistent/sbptt/x.csv",
                         "ulimit -v 4000000; ");
    INFO(r.output);
    CHECK(r.status == 1);
    CHECK(r.output.find("quantum: --csv '/nonexistent/sbptt/x.csv': directory "
                        "'/nonexistent/sbptt' does not exist") != std::string::npos);
    CHECK(r.output.find("GiB") == std::string::npos);
  }

  // The checkpoint's lock file is no place for an output: a log renamed over it left a second
  // run of the same command a lock of its own, and both trained on one checkpoint.
  const fs::path dir = fs::path(scratch("lock_role"));
  fs::create_directories(dir);
  const std::string checkpoint = (dir / "ck").string();
  const Result lock = run("cartpole", "--epochs 1 --samples 8 --csv " + checkpoint +
                                          ".lock --checkpoint " + checkpoint);
  INFO(lock.output);
  CHECK(lock.status == 1);
  CHECK(lock.output.find("cartpole: --csv '" + checkpoint +
                         ".lock' and --checkpoint's lock file '" + checkpoint +
                         ".lock' are the same file") != std::string::npos);
  CHECK_FALSE(fs::exists(checkpoint));
}

TEST_CASE("a loop of symbolic links is refused naming the flag that gave it", "[programs]") {
  // "'loop1': too many levels of symbolic links", of which of the flags the user had to guess.
  const fs::path dir = fs::path(scratch("link_loop"));
  fs::create_directories(dir);
  const fs::path loop1 = dir / "loop1", loop2 = dir / "loop2";
  fs::remove(loop1);
  fs::remove(loop2);
  fs::create_symlink(loop2, loop1);
  fs::create_symlink(loop1, loop2);
  for (const auto& [program, flag] :
       {std::pair{"cartpole", "--save-params"}, std::pair{"cartpole", "--csv"},
        std::pair{"cartpole", "--checkpoint"}, std::pair{"cartpole", "--init-params"},
        std::pair{"rotation", "--csv"}, std::pair{"mujoco", "--model"}}) {
    const std::string rest = std::string(program) == "mujoco"     ? " --target 0"
                             : std::string(program) == "rotation" ? " --iterations 1"
                                                                  : " --epochs 1";
    const Result r = run(program, std::string(flag) + " " + loop1.string() + rest);
    INFO(program << " " << flag << "\n" << r.output);
    CHECK(r.status == 1);
    CHECK(r.output.find(std::string(program) + ": " + flag + ": '" + loop1.string() +
                        "': too many levels of symbolic links") != std::string::npos);
  }
}

TEST_CASE("reproduce hands a relative --out that starts with -- to its programs as a path",
          "[programs]") {
  // docs/programs.md tells users to write such a value --out=--results; the runner then passed
  // "--csv --results/runs/…" on, which every task program refused (exit 2): every run failed.
  const fs::path dir = fs::path(scratch("dash_out"));
  fs::remove_all(dir);
  fs::create_directories(dir);
  // The plotting script was handed it as given, and took it for an option of its own.
  const Result r = run("reproduce", "--tasks cartpole --complexities 1 --methods R --clips norm "
                                    "--seeds 1 --epochs 2 --samples 8 --out=--results",
                       "cd '" + dir.string() + "' && ");
  INFO(r.output);
  CHECK(r.status == 0);
  CHECK(fs::exists(dir / "--results" / "runs" / "cartpole_p1_R_norm_s42.csv"));
  if (r.output.find("no python3 with matplotlib") == std::string::npos) {
    CHECK(r.output.find("warning") == std::string::npos);
    CHECK_FALSE(fs::is_empty(dir / "--results" / "plots"));
  }
}

namespace {

/// Runs `command` (a program of the build with its flags) in the background with its output
/// in `dir`, sends it SIGTERM once the shell test `ready` holds (at most 120 s), and returns
/// "exit <code>" as the shell saw it.
std::string terminated_when(const fs::path& dir, const std::string& command,
                            const std::string& ready) {
  std::ofstream(dir / "run.sh") << sbptt::testing::examples_dir() << "/" << command << " > "
                                << (dir / "out").string() << " 2>&1 & pid=$!\ni=0; until "
                                << ready << "; do i=$((i+1)); [ $i -gt 1200 ] && break; "
                                << "sleep 0.1; done\nkill -TERM $pid; wait $pid; echo exit $? > "
                                << (dir / "said").string() << "\n";
  REQUIRE(std::system(("sh " + (dir / "run.sh").string()).c_str()) == 0);
  return sbptt::testing::file_text(dir / "said");
}

}  // namespace

TEST_CASE("bench and accuracy keep the rows of their --csv measured before a signal",
          "[programs]") {
  // Their CSV was written at the end alone: a SIGTERM in the minutes of measuring lost every
  // row.
  const fs::path dir = fs::path(scratch("csv_signal"));
  fs::remove_all(dir);
  fs::create_directories(dir);
  const fs::path csv = dir / "b.csv";
  const std::string bench = terminated_when(
      dir, "bench --tasks cartpole1 --scalars float,double --methods RC --repeats 1 --csv " +
               csv.string(),
      "grep -q '^cartpole1 *float' " + (dir / "out").string());
  INFO(bench << sbptt::testing::file_text(dir / "out"));
  CHECK(bench == "exit 143\n");
  CHECK(sbptt::testing::file_text(csv).starts_with("task,scalar,method,"));
  CHECK(sbptt::testing::file_text(csv).find("\ncartpole1,float,R,") != std::string::npos);

  fs::remove(csv);
  const std::string accuracy =
      terminated_when(dir, "accuracy --csv " + csv.string(), "[ -f " + csv.string() + " ]");
  INFO(accuracy << sbptt::testing::file_text(dir / "out"));
  CHECK(accuracy == "exit 143\n");
  CHECK(sbptt::testing::file_text(csv).find("\ncartpole,dt,double,") != std::string::npos);
}

TEST_CASE("bench_mujoco checks --source before measuring: exit 1, naming the flag", "[programs]") {
  // Found by a fault probe: the table's header came first, then exit 2 (a bad flag's code) with
  // load_mujoco_model's message, which did not name --source.
  const fs::path empty = scratch("source_without_models");
  fs::create_directories(empty);
  for (const std::string& source : {std::string("/nonexistent/sbptt"), empty.string()}) {
    const Result r = run("bench_mujoco", "--repeats 1 --source " + source);
    INFO(r.output);
    CHECK(r.status == 1);
    CHECK(r.output.starts_with("bench_mujoco: --source '" + source + "': "));
    CHECK(r.output.find("expected the sbptt source tree") != std::string::npos);
    CHECK(r.output.find("step ns") == std::string::npos);  // nothing was printed before
  }
}

TEST_CASE("every program that prints timings states the instruction set it was built for",
          "[programs]") {
  // The programs are built with this test's flags, so its own instruction_set() is theirs
  // (test_core_instruction_set checks that name against the CPU and Eigen's packets).
  const std::string expected = sbptt::instruction_set();
  const fs::path out = scratch("isa_dry_run");
  struct Case {
    std::string program, arguments;
  };
  for (const Case& c :
       {Case{"cartpole", "--epochs 0 --samples 2"}, Case{"guidance", "--epochs 0 --samples 2"},
        Case{"quantum", "--epochs 0 --samples 2"},
        Case{"bench", "--tasks cartpole1 --scalars float --methods R --repeats 1"},
        Case{"bench_mujoco", "--repeats 1"}, Case{"accuracy", "--integrators-only"},
        Case{"reproduce", "--dry-run --tasks cartpole --complexities 1 --methods R --seeds 1 "
                          "--epochs 1 --samples 2 --out " + out.string()}}) {
    const Result r = run(c.program, c.arguments);
    INFO(c.program << " " << c.arguments << "\n" << r.output);
    CHECK(r.status == 0);
    CHECK(r.output.find(expected) != std::string::npos);
  }
}

TEST_CASE("bench --threads 2 times the evaluation beside the next epoch's training",
          "[programs]") {
  const fs::path csv = scratch("bench_beside.csv");
  const Result r = run("bench", "--tasks cartpole4 --scalars float --methods R --repeats 1 "
                                "--threads 2 --csv " + csv.string());
  INFO(r.output);
  REQUIRE(r.status == 0);
  const std::string line = "cartpole4 float R: the evaluation beside the next epoch's training "
                           "(one thread each) ";
  const std::size_t at = r.output.find(line);
  REQUIRE(at != std::string::npos);
  const double printed = std::strtod(r.output.c_str() + at + line.size(), nullptr);
  // The CSV's two columns of it: the printed speed-up is their ratio.
  std::ifstream in(csv);
  std::string header, row;
  REQUIRE(std::getline(in, header));
  REQUIRE(std::getline(in, row));
  auto column = [](const std::string& text, std::size_t index) {
    std::istringstream fields(text);
    std::string field;
    for (std::size_t i = 0; i <= index; ++i) std::getline(fields, field, ',');
    return field;
  };
  auto index_of = [&](const std::string& name) {
    for (std::size_t i = 0;; ++i) {
      const std::string field = column(header, i);
      if (field == name) return i;
      REQUIRE(i < 100);
    }
  };
  const double beside = std::stod(column(row, index_of("ms_epoch_beside")));
  const double alone = std::stod(column(row, index_of("ms_epoch_beside_alone")));
  REQUIRE(beside > 0);
  REQUIRE(alone > 0);
  CHECK(printed == Approx(alone / beside).epsilon(0.01));
}

TEST_CASE("accuracy runs every study to its end", "[programs][slow]") {
  // The default case above runs only the integrator axis: the whole program takes 16 s in a
  // Release build and 147 s under the sanitizers (docs/testing.md).
  const Result r = run("accuracy", "");
  INFO(r.output);
  CHECK(r.status == 0);
  for (const std::string sim : {"cartpole ", "guidance ", "quantum "})
    CHECK(r.output.find("\n" + sim) != std::string::npos);
}
