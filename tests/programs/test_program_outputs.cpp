// What the task programs do with their files (issue "faults that lose work"): the log grows by
// appending, a failed log write keeps the parameters, paths are checked up front (empty,
// too long, one file under two names), links and permissions survive, and a run killed with
// SIGKILL at random moments and rerun with --checkpoint ends bit for bit as an uninterrupted one.
//
// SBPTT_EXAMPLES_DIR (environment) runs these tests against other builds of the programs
// (`examples_dir()`, program_runner.hpp).
#include <catch2/catch.hpp>

#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "programs/program_runner.hpp"
#include "sbptt/nn/parameters_io.hpp"
#include "sbptt/train/stop_signals.hpp"
#include "support/address_sanitizer.hpp"
#include "support/files.hpp"

namespace fs = std::filesystem;
using sbptt::testing::examples_dir;
using sbptt::testing::file_text;
using sbptt::testing::fresh_directory;
using sbptt::testing::without_seconds;

namespace {

struct Outcome {
  int status = -1;  ///< exit code, or -signal
  std::string output;
  long long bytes_written = 0;  ///< wchar of /proc/<pid>/io: bytes passed to write(2) & co.
  long long writes = 0;         ///< syscw: write system calls
};

/// Runs `program` with `arguments` through `sh -c` (`prefix` goes first, e.g. a ulimit);
/// output goes to a file. While it runs, `kill_when` is asked every 100 µs; once it says
/// true, the process gets `kill_signal`.
Outcome launch(const std::string& program, const std::string& arguments,
               const std::string& prefix = "", const std::function<bool()>& kill_when = {},
               const std::string& wrapper = "", int kill_signal = SIGKILL) {
  const fs::path output =
      fs::temp_directory_path() / ("sbptt_outputs_" + std::to_string(getpid()) + ".out");
  const std::string command =
      prefix + "exec " + wrapper + examples_dir() + "/" + program + " " + arguments + " > " +
      output.string() + " 2>&1";
  const pid_t pid = fork();
  REQUIRE(pid >= 0);
  if (pid == 0) {
    // The program starts with the stop signals at their default (then `prefix` may ignore
    // them), whatever this test program was started ignoring (nohup ignores SIGHUP).
    for (const int stop : {SIGINT, SIGTERM, SIGHUP}) signal(stop, SIG_DFL);
    execl("/bin/sh", "sh", "-c", command.c_str(), static_cast<char*>(nullptr));
    _exit(127);
  }
  siginfo_t info{};
  while (kill_when) {
    info.si_pid = 0;
    if (waitid(P_PID, static_cast<id_t>(pid), &info, WEXITED | WNOHANG | WNOWAIT) != 0 ||
        info.si_pid != 0)
      break;  // it ended by itself
    if (kill_when()) {
      kill(pid, kill_signal);
      break;
    }
    std::this_thread::sleep_for(std::chrono::microseconds(100));
  }
  REQUIRE(waitid(P_PID, static_cast<id_t>(pid), &info, WEXITED | WNOWAIT) == 0);
  Outcome outcome;
  std::ifstream io("/proc/" + std::to_string(pid) + "/io");  // still there: not yet reaped
  std::string key;
  long long value = 0;
  while (io >> key >> value) {
    if (key == "wchar:") outcome.bytes_written = value;
    if (key == "syscw:") outcome.writes = value;
  }
  int status = 0;
  REQUIRE(waitpid(pid, &status, 0) == pid);
  outcome.status = WIFEXITED(status) ? WEXITSTATUS(status) : -WTERMSIG(status);
  std::ifstream text(output);
  outcome.output.assign(std::istreambuf_iterator<char>(text), {});
  return outcome;
}

/// `name` in a directory of this process, emptied once at the first call.
fs::path scratch(const std::string& name) {
  static const fs::path dir = fresh_directory("outputs_files");
  return dir / name;
}

bool contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

}  // namespace

TEST_CASE("--csv appends: each byte of the log is written once", "[programs]") {
  // Rewriting the whole log each epoch writes ~epochs/2 times the final size.
  const fs::path log = scratch("linear.csv");
  const std::string run = "--epochs 3000";
  const Outcome without = launch("toy", run);
  const Outcome with = launch("toy", run + " --csv " + log.string());
  REQUIRE(without.status == 0);
  REQUIRE(with.status == 0);
  const auto size = static_cast<long long>(fs::file_size(log));
  INFO("log " << size << " bytes; bytes written with --csv " << with.bytes_written
              << ", without " << without.bytes_written);
  CHECK(size > 3000 * 40);
  CHECK(with.bytes_written - without.bytes_written <= size + 4096);
  CHECK(with.writes - without.writes <= 3000 + 16);
}

TEST_CASE("a log that cannot be written keeps the trained parameters", "[programs]") {
  // A file-size limit fails the log's writes with EFBIG, as a full disk does (the programs
  // ignore SIGXFSZ, which would kill them silently).
  const fs::path log = scratch("full.csv"), params = scratch("kept.params");
  fs::remove(params);
  const Outcome r = launch("toy", "--epochs 2000 --csv " + log.string() + " --save-params " +
                                      params.string(), "ulimit -f 16; ");
  INFO(r.output);
  CHECK(r.status == 1);
  CHECK(contains(r.output, log.string()));
  REQUIRE(contains(r.output, "were saved to '" + params.string() + "'"));
  // The parameters are those of a clean run of as many epochs as the message names.
  const auto at = r.output.find("parameters after epoch ");
  REQUIRE(at != std::string::npos);
  const long epochs = std::stol(r.output.substr(at + 23));
  CHECK(epochs > 10);
  const fs::path clean = scratch("clean.params");
  REQUIRE(launch("toy", "--epochs " + std::to_string(epochs) + " --save-params " +
                            clean.string()).status == 0);
  CHECK(file_text(params) == file_text(clean));
}

TEST_CASE("a file beyond a file-size limit is an error naming it, not a silent death",
          "[programs]") {
  const fs::path dir = fresh_directory("file_size_limit");
  struct Case {
    std::string program, arguments, file;
  };
  for (const Case& c :
       {Case{"cartpole", "--epochs 3 --samples 8 --save-params " + (dir / "p.txt").string(),
             (dir / "p.txt").string()},
        Case{"train_own_scene", dir.string(), (dir / "run.checkpoint").string()}}) {
    const Outcome r = launch(c.program, c.arguments, "ulimit -f 16; ");
    INFO(c.program << " " << c.arguments << "\n" << r.output);
    CHECK(r.status == 1);
    CHECK(contains(r.output, c.file));
    CHECK(contains(r.output, "File too large"));
  }
}

TEST_CASE("train_own_scene: a checkpoint that cannot be written is named, and so are the "
          "parameters it saved", "[programs]") {
  // 100 blocks of 512 bytes (dash's unit; bash's is 1024) hold best.params (about 25 kB) but
  // not the checkpoint, which holds Adam's moments too. The message named only the checkpoint.
  const fs::path dir = fresh_directory("own_scene_checkpoint_limit");
  const Outcome r = launch("train_own_scene", dir.string(), "ulimit -f 100; ");
  INFO(r.output);
  CHECK(r.status == 1);
  CHECK(contains(r.output, (dir / "run.checkpoint").string() + "' failed: File too large"));
  CHECK(contains(r.output, "were saved to '" + (dir / "best.params").string() + "'"));
  CHECK(fs::exists(dir / "best.params"));
}

TEST_CASE("output cut short by a file-size limit ends with exit 1, not 0", "[programs]") {
  // The progress lines of 2000 epochs (about 12 KiB) into a file limited to 4 KiB (8 blocks
  // of dash's 512 bytes, or of bash's 1024), as `reproduce` keeps a run's log
  // (runs/<name>.log). Before: the log ended early and the exit code was 0.
  const Outcome whole = launch("toy", "--epochs 2000");
  REQUIRE(whole.status == 0);
  const Outcome r = launch("toy", "--epochs 2000", "ulimit -f 8; ");
  INFO(r.output);
  CHECK(r.output.size() <= 8192);
  CHECK(r.output.size() < whole.output.size());
  CHECK(r.status == 1);
}

TEST_CASE("stdout that cannot be written: exit 1, and stderr gives the reason", "[programs]") {
  // stderr into the pipe, stdout into /dev/full (every write fails with ENOSPC).
  // lqr_convergence, whose study takes a minute, and bench stop after their first line.
  const std::string csv = scratch("full_stdout.csv").string();
  const fs::path own_scene = fresh_directory("full_stdout_own_scene");
  for (const auto& [program, arguments] : std::vector<std::pair<std::string, std::string>>{
           {"toy", "--epochs 5"},
           {"custom_simulator", ""},
           {"train_own_scene", own_scene.string()},
           {"rotation", "--iterations 5 --csv " + csv},
           {"accuracy", "--integrators-only --csv " + csv},
           {"lqr_convergence", ""},
           {"bench", "--tasks cartpole1 --scalars float --methods R --repeats 1"},
           {"bench_mujoco", "--repeats 1"}}) {
    const auto r = sbptt::testing::run(program, arguments, "", "2>&1 >/dev/full");
    INFO(program << "\n" << r.output);
    CHECK(r.status == 1);
    CHECK(contains(r.output, program + ": standard output" +
                                 (program == "train_own_scene" || program == "custom_simulator"
                                      ? " was not written in full"
                                      : " or standard error was not written in full: No space "
                                        "left on device")));
  }
}

TEST_CASE("a usage (--help) that stdout cannot take: exit 1, not 0", "[programs]") {
  // The usage is the whole output of --help: a script that reads it must learn that it is
  // missing, as with every other output.
  for (const std::string program :
       {"toy", "cartpole", "guidance", "quantum", "mujoco", "rotation", "accuracy",
        "lqr_convergence", "bench", "bench_mujoco", "custom_simulator", "train_own_scene",
        "reproduce"}) {
    const auto r = sbptt::testing::run(program, "--help", "", "2>&1 >/dev/full");
    INFO(program << "\n" << r.output);
    CHECK(r.status == 1);
    CHECK(contains(r.output, program + ": standard output"));
  }
}

TEST_CASE("rotation refuses a --csv it could not write before the study", "[programs]") {
  const fs::path dir = fresh_directory("rotation_csv");
  const fs::path fifo = dir / "pipe";
  REQUIRE(::mkfifo(fifo.c_str(), 0666) == 0);
  for (const fs::path& csv : {fifo, dir / "missing" / "r.csv"}) {
    const Outcome r = launch("rotation", "--iterations 5 --csv " + csv.string());
    INFO(r.output);
    CHECK(r.status == 1);
    CHECK(contains(r.output, "rotation: --csv '" + csv.string() + "'"));
    CHECK_FALSE(contains(r.output, "iteration"));
  }
  CHECK(fs::is_fifo(fifo));
}

TEST_CASE("a name too long for its temporary file fails before training", "[programs]") {
  // 234 bytes is a legal name, but not with the temporary suffix added beside it.
  const fs::path params = scratch(std::string(234, 'p'));
  const Outcome r = launch("toy", "--epochs 5 --save-params " + params.string());
  INFO(r.output);
  CHECK(r.status == 1);
  CHECK(contains(r.output, "--save-params"));
  CHECK(contains(r.output, "limit of 255 bytes"));
  CHECK_FALSE(contains(r.output, "epoch 1"));
}

TEST_CASE("empty paths are refused with exit 2, naming the flag", "[programs]") {
  for (const std::string flag :
       {"--save-params", "--csv", "--init-params", "--init-states", "--dump-gradients",
        "--checkpoint"}) {
    const Outcome r = launch("toy", "--epochs 1 " + flag + " ''");
    INFO(flag << "\n" << r.output);
    CHECK(r.status == 2);
    CHECK(contains(r.output, flag + " '' is an empty path"));
  }
}

TEST_CASE("two outputs, or an input and an output, that are one file are refused",
          "[programs]") {
  const fs::path dir = fresh_directory("same");
  const fs::path params = dir / "same.txt";
  REQUIRE(launch("toy", "--epochs 1 --save-params " + params.string()).status == 0);
  const std::string before = file_text(params);
  fs::create_hard_link(params, dir / "hard.txt");
  fs::create_symlink(params, dir / "soft.txt");
  const std::string dot = (dir / "." / "same.txt").string();
  for (const std::string& arguments :
       {"--init-params " + params.string() + " --save-params " + params.string() + " --csv " +
            params.string(),
        "--init-params " + params.string() + " --save-params " + dot,
        "--init-params " + (dir / "hard.txt").string() + " --save-params " + params.string(),
        "--csv " + (dir / "soft.txt").string() + " --init-params " + params.string(),
        "--csv " + (dir / "new.csv").string() + " --save-params " + (dir / "." / "new.csv").string(),
        "--checkpoint " + (dir / "new.csv").string() + " --csv " + (dir / "new.csv").string()}) {
    const Outcome r = launch("toy", "--epochs 3 " + arguments);
    INFO(arguments << "\n" << r.output);
    CHECK(r.status == 1);
    CHECK(contains(r.output, "are the same file"));
    CHECK_FALSE(contains(r.output, "epoch 1"));
    CHECK(file_text(params) == before);
    CHECK_FALSE(fs::exists(dir / "new.csv"));
  }
}

TEST_CASE("an output that is the program's own stdout or stderr is refused before any work",
          "[programs]") {
  // Streams redirected to a file: the finished output would be renamed over that file, and all
  // the program printed afterwards would go to the old, unlinked one (and its exit code be 0).
  for (const std::string flag : {"--csv", "--save-params", "--dump-gradients", "--checkpoint"}) {
    for (const std::string stream : {"/dev/stdout", "/dev/stderr"}) {
      const std::string epochs = flag == "--dump-gradients" ? "" : "--epochs 2 ";
      const Outcome r = launch("toy", epochs + flag + " " + stream);  // > file 2>&1
      INFO(flag << " " << stream << "\n" << r.output);
      CHECK(r.status == 1);
      CHECK(contains(r.output, flag + " '" + stream +
                                   "' is this program's standard output and error; expected"));
      CHECK_FALSE(contains(r.output, "epoch 1"));
      CHECK_FALSE(contains(r.output, "epoch,batch_loss"));
    }
  }
  // Only stderr to a file, or only stdout (stderr on the pipe).
  const fs::path errors = scratch("stderr.txt"), printed = scratch("stdout.txt");
  const auto error_alone = sbptt::testing::run("toy", "--epochs 2 --csv /dev/stderr", "",
                                               "2> " + errors.string());
  INFO(file_text(errors));
  CHECK(error_alone.status == 1);
  CHECK(contains(file_text(errors), "--csv '/dev/stderr' is this program's standard error;"));
  const auto output_alone = sbptt::testing::run("toy", "--epochs 2 --csv /dev/stdout", "",
                                                "2>&1 > " + printed.string());
  INFO(output_alone.output);
  CHECK(output_alone.status == 1);
  CHECK(contains(output_alone.output, "--csv '/dev/stdout' is this program's standard output;"));
  // Through a pipe: a special file, refused as such before any work, naming the flag.
  const auto piped = sbptt::testing::run("toy", "--epochs 2 --csv /dev/stdout");
  INFO(piped.output);
  CHECK(piped.status == 1);
  CHECK(contains(piped.output, "--csv '/dev/stdout' exists and is not a regular file"));
  CHECK_FALSE(contains(piped.output, "epoch,batch_loss"));
}

TEST_CASE("a symbolic link as --csv gets its target written", "[programs]") {
  const fs::path dir = fresh_directory("link");
  fs::create_directories(dir / "real");
  std::ofstream(dir / "real" / "log.csv") << "old\n";
  fs::create_symlink(dir / "real" / "log.csv", dir / "link.csv");
  const Outcome r = launch("toy", "--epochs 3 --csv " + (dir / "link.csv").string());
  INFO(r.output);
  REQUIRE(r.status == 0);
  CHECK(fs::is_symlink(fs::symlink_status(dir / "link.csv")));
  CHECK(file_text(dir / "real" / "log.csv").rfind("epoch,batch_loss", 0) == 0);
}

TEST_CASE("a replaced output keeps its owner and permission bits", "[programs]") {
  const fs::path params = fresh_directory("mode") / "p.txt";
  std::ofstream(params) << "0\n0\n";
  REQUIRE(chmod(params.c_str(), 0604) == 0);
  const bool root = geteuid() == 0;
  if (root) REQUIRE(chown(params.c_str(), 65534, 65534) == 0);  // nobody's file
  const Outcome r = launch("toy", "--epochs 3 --save-params " + params.string());
  INFO(r.output);
  REQUIRE(r.status == 0);
  struct stat info {};
  REQUIRE(stat(params.c_str(), &info) == 0);
  CHECK((info.st_mode & 07777) == 0604);
  if (root) CHECK(info.st_uid == 65534);
  CHECK(file_text(params) != "0\n0\n");
}

/// A short cart-pole run in `dir` (log.csv, p.txt), done once uninterrupted: its parameters
/// and log, the outputs then removed for the interrupted runs to write again.
struct CartPoleRun {
  fs::path dir, log_path;
  std::string common;  ///< the flags of the run
  std::string params, log;

  CartPoleRun(const std::string& directory, const std::string& variant)
      : dir(fresh_directory(directory)), log_path(dir / "log.csv"),
        common("--poles 2 --samples 16 --steps 40 --batch 2 --epochs 30 " + variant + " --csv " +
               log_path.string() + " --save-params " + (dir / "p.txt").string()) {
    const Outcome whole = launch("cartpole", common);
    REQUIRE(whole.status == 0);
    params = file_text(dir / "p.txt");
    log = file_text(log_path);
    fs::remove(dir / "p.txt");
    fs::remove(log_path);
  }

  /// Rows of the log so far (the header aside; a row being written counts once complete).
  [[nodiscard]] long rows() const {
    const std::string text = file_text(log_path);
    return text.empty() ? 0L : static_cast<long>(std::count(text.begin(), text.end(), '\n')) - 1;
  }
};

TEST_CASE("killed with SIGKILL at random epochs, a rerun with --checkpoint ends bit for bit "
          "as one uninterrupted run", "[programs]") {
  std::mt19937 random(12345);
  for (const std::string variant : {"--method R", "--method C", "--method R --float",
                                    "--method C --float"}) {
    const CartPoleRun run("kill", "--shuffle " + variant);
    const auto& [dir, log_path, common, params, log] = run;
    const auto rows = [&] { return run.rows(); };
    const std::string resumable = common + " --checkpoint " + (dir / "run.checkpoint").string();
    int kills = 0, resumes = 0;
    long killed_at = 0;
    Outcome last;
    for (int attempt = 0; attempt < 10; ++attempt) {
      // Four kills, each a random 1 to 6 epochs after the last one's; then it may finish.
      const long target = std::min(29L, killed_at + std::uniform_int_distribution<long>(1, 6)(random));
      std::function<bool()> kill_when;
      if (attempt < 4) kill_when = [&] { return rows() >= target; };
      last = launch("cartpole", resumable, "", kill_when);
      resumes += contains(last.output, "resuming after epoch") ? 1 : 0;
      // Nothing half-written is ever left beside the outputs.
      for (const auto& entry : fs::directory_iterator(dir))
        CHECK_FALSE(contains(entry.path().filename().string(), ".tmp."));
      if (last.status == -SIGKILL) {
        ++kills;
        killed_at = rows();
      }
      if (last.status == 0) break;
    }
    INFO(variant << ": " << kills << " kills, " << resumes << " resumes\n" << last.output);
    REQUIRE(last.status == 0);
    CHECK(kills >= 3);
    CHECK(resumes >= 3);
    CHECK(file_text(dir / "p.txt") == params);
    CHECK(without_seconds(file_text(log_path)) == without_seconds(log));
  }
}

TEST_CASE("SIGINT, SIGTERM or SIGHUP stops after the current epoch, keeps its work and says "
          "so; the rerun ends bit for bit as one uninterrupted run", "[programs]") {
  // Checkpoints only every 1000 epochs: what the rerun resumes from is written on the signal.
  // SIGHUP (a closed terminal) killed the run at once, its parameters unsaved.
  for (const int signal : {SIGINT, SIGTERM, SIGHUP}) {
    const std::string name = sbptt::signal_name(signal);
    const CartPoleRun run("interrupt", "");
    const auto& [dir, log_path, common, params, log] = run;
    const auto rows = [&] { return run.rows(); };
    const std::string resumable = common + " --checkpoint " + (dir / "run.checkpoint").string() +
                                  " --checkpoint-every 1000";
    const Outcome stopped =
        launch("cartpole", resumable, "", [&] { return rows() >= 3; }, "", signal);
    INFO(name << "\n" << stopped.output);
    REQUIRE(stopped.status == 128 + signal);
    const long done = rows();
    CHECK(done >= 3);
    CHECK(done < 30);
    CHECK(contains(stopped.output, "stopped by " + name + " after epoch " + std::to_string(done)));
    CHECK(contains(stopped.output, "run the same command again to resume"));
    // Said when the signal comes, not only after the epoch (which may take minutes).
    CHECK(contains(stopped.output, "cartpole: " + name + ": stopping after the current epoch, "
                                   "which keeps its work; a second " + name + " stops at once"));
    CHECK(fs::exists(dir / "p.txt"));
    const Outcome rerun = launch("cartpole", resumable);
    REQUIRE(rerun.status == 0);
    CHECK(contains(rerun.output, "resuming after epoch " + std::to_string(done)));
    CHECK(file_text(dir / "p.txt") == params);
    CHECK(without_seconds(file_text(log_path)) == without_seconds(log));
  }
}

TEST_CASE("a run started with SIGINT ignored, as a shell starts a background job, ends as if "
          "it never came", "[programs]") {
  const CartPoleRun run("ignored", "");
  const auto& [dir, log_path, common, params, log] = run;
  const Outcome r =
      launch("cartpole", common, "trap '' INT; ", [&] { return run.rows() >= 3; }, "", SIGINT);
  INFO(r.output);
  REQUIRE(r.status == 0);
  CHECK_FALSE(contains(r.output, "stopped by"));
  CHECK(file_text(dir / "p.txt") == params);
  CHECK(without_seconds(file_text(log_path)) == without_seconds(log));
}

/// The epoch that the checkpoint at `path` was written after, as the file states it.
std::string checkpoint_epoch(const fs::path& path) {
  const std::string checkpoint = file_text(path);
  const std::size_t epoch_line = checkpoint.find("\nepoch ");
  REQUIRE(epoch_line != std::string::npos);
  const std::size_t start = epoch_line + 7;
  return checkpoint.substr(start, checkpoint.find('\n', start) - start);
}

TEST_CASE("train_own_scene rerun in its directory says that it resumed, and from which epoch",
          "[programs]") {
  const fs::path dir = fresh_directory("own_scene_resume");
  const Outcome first = launch("train_own_scene", dir.string());
  REQUIRE(first.status == 0);
  CHECK_FALSE(contains(first.output, "resumed"));
  const std::string epoch = checkpoint_epoch(dir / "run.checkpoint");
  const Outcome again = launch("train_own_scene", dir.string());
  INFO(again.output);
  CHECK(again.status == 0);
  CHECK(contains(again.output, "resumed from the checkpoint of epoch " + epoch + "\n"));
}

TEST_CASE("train_own_scene stopped by SIGINT or SIGTERM keeps its work and says so; the rerun "
          "ends bit for bit as one uninterrupted run", "[programs]") {
  // Found by a fault probe: it died by the signal's default action, best.params unwritten and
  // the log possibly an epoch ahead of the checkpoint.
  const fs::path whole = fresh_directory("own_scene_whole");
  REQUIRE(launch("train_own_scene", whole.string()).status == 0);
  const std::string params = file_text(whole / "best.params");
  const std::string log = file_text(whole / "log.csv");
  for (const int signal : {SIGINT, SIGTERM}) {
    const std::string name = signal == SIGINT ? "SIGINT" : "SIGTERM";
    const fs::path dir = fresh_directory("own_scene_" + name);
    const auto rows = [&] {
      const std::string text = file_text(dir / "log.csv");
      return text.empty() ? 0L : static_cast<long>(std::count(text.begin(), text.end(), '\n')) - 1;
    };
    const Outcome stopped =
        launch("train_own_scene", dir.string(), "", [&] { return rows() >= 3; }, "", signal);
    INFO(name << "\n" << stopped.output);
    REQUIRE(stopped.status == 128 + signal);
    const long done = rows();
    CHECK(done >= 3);
    CHECK(checkpoint_epoch(dir / "run.checkpoint") == std::to_string(done));
    CHECK(contains(stopped.output, "train_own_scene: " + name + ": stopping after the current "
                                   "epoch, which keeps its work; a second " + name +
                                   " stops at once"));
    CHECK(contains(stopped.output, "stopped by " + name + " after epoch " +
                                       std::to_string(done) + "; run it again to resume"));
    CHECK(fs::exists(dir / "best.params"));
    const Outcome rerun = launch("train_own_scene", dir.string());
    INFO(rerun.output);
    REQUIRE(rerun.status == 0);
    CHECK(contains(rerun.output, "resumed from the checkpoint of epoch " + std::to_string(done)));
    CHECK(file_text(dir / "best.params") == params);
    CHECK(without_seconds(file_text(dir / "log.csv")) == without_seconds(log));
  }
}

TEST_CASE("a checkpoint of other settings is refused, naming the setting", "[programs]") {
  const fs::path dir = fresh_directory("settings");
  const std::string checkpoint = "--epochs 2 --checkpoint " + (dir / "c").string();
  REQUIRE(launch("toy", checkpoint).status == 0);
  const Outcome r = launch("toy", checkpoint + " --lr 0.02");
  INFO(r.output);
  CHECK(r.status == 2);
  CHECK(contains(r.output, "was made with --lr = 0.01; this run has --lr = 0.02"));
  CHECK_FALSE(contains(r.output, "epoch 1"));
  // The file holds 17 digits; the message showed them ("--lr = 0.0050000000000000001").
  const Outcome digits = launch("toy", checkpoint + " --lr 0.005");
  INFO(digits.output);
  CHECK(digits.status == 2);
  CHECK(contains(digits.output, "; this run has --lr = 0.005; expected the same settings"));
  const Outcome seed = launch("toy", checkpoint + " --seed 7");
  INFO(seed.output);
  CHECK(seed.status == 2);
  CHECK(contains(seed.output, "; this run has --seed = 7"));
}

TEST_CASE("a checkpoint resumed with another --csv, or with its log deleted, names --csv and "
          "says what it needs", "[programs]") {
  const fs::path dir = fresh_directory("other_log");
  const std::string checkpoint = "--checkpoint " + (dir / "c").string();
  const fs::path log = dir / "log.csv";
  for (const bool deleted : {true, false}) {
    fs::remove(dir / "c");
    REQUIRE(launch("toy", "--epochs 2 --csv " + log.string() + " " + checkpoint).status == 0);
    if (deleted) fs::remove(log);
    const fs::path given = deleted ? log : dir / "other.csv";
    const Outcome r = launch("toy", "--epochs 4 --csv " + given.string() + " " + checkpoint);
    INFO(r.output);
    CHECK(r.status == 1);
    CHECK(contains(r.output, "--csv '" + given.string() + "': "));
    CHECK(contains(r.output, "expected --csv to name that log, or no checkpoint to start over"));
    CHECK_FALSE(contains(r.output, "epoch 1"));
  }
}

TEST_CASE("every finished file is synced, renamed, and its directory synced", "[programs]") {
  // strace shows the order of the calls: fsync(file), rename(temporary, target), fsync(dir).
  if (std::system("command -v strace > /dev/null 2>&1") != 0) return;  // not installed
  // LeakSanitizer aborts a program that runs under ptrace, so strace cannot watch an ASan build.
  if (sbptt::testing::address_sanitizer) return;
  const fs::path dir = fresh_directory("durable");
  const fs::path trace = dir / "trace.txt";
  const Outcome r = launch("toy", "--epochs 3 --csv " + (dir / "log.csv").string() +
                                      " --save-params " + (dir / "p.txt").string() +
                                      " --checkpoint " + (dir / "run.checkpoint").string(),
                           "", {}, "strace -f -y -o " + trace.string() +
                                       " -e trace=fsync,fdatasync,rename,renameat,renameat2 ");
  REQUIRE(r.status == 0);
  std::vector<std::string> calls;
  std::istringstream in(file_text(trace));
  for (std::string line; std::getline(in, line);)
    if (contains(line, "fsync(") || contains(line, "rename")) calls.push_back(line);
  int renames = 0;
  const std::string synced_dir = "<" + dir.string() + ">)";
  for (std::size_t i = 0; i < calls.size(); ++i) {
    if (!contains(calls[i], "rename")) continue;
    ++renames;
    INFO(calls[i]);
    REQUIRE(i > 0);
    REQUIRE(i + 1 < calls.size());
    CHECK(contains(calls[i - 1], "fsync(")); // the file's data first
    CHECK(contains(calls[i - 1], "<" + dir.string() + "/"));
    CHECK(contains(calls[i + 1], "fsync(")); // then the directory entry
    CHECK(contains(calls[i + 1], synced_dir));
  }
  CHECK(renames == 1 + 3 + 1);  // the log's header, a checkpoint per epoch, the parameters
}
