// What the task programs do with their files (issue "faults that lose work"): the log grows by
// appending, a failed log write keeps the parameters, paths are checked up front (empty,
// too long, one file under two names), links and permissions survive, and a run killed with
// SIGKILL at random moments and rerun with --checkpoint ends bit for bit as an uninterrupted one.
//
// SBPTT_EXAMPLES_DIR (environment) overrides the programs' directory, to run these tests
// against other builds of the programs (e.g. those from before the fixes).
#include <catch2/catch.hpp>

#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <optional>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "sbptt/nn/parameters_io.hpp"

namespace fs = std::filesystem;

namespace {

std::string examples_dir() {
  const char* override_dir = std::getenv("SBPTT_EXAMPLES_DIR");
  return override_dir != nullptr ? override_dir : SBPTT_EXAMPLES_DIR;
}

struct Outcome {
  int status = -1;  ///< exit code, or -signal
  std::string output;
  long long bytes_written = 0;  ///< wchar of /proc/<pid>/io: bytes passed to write(2) & co.
  long long writes = 0;         ///< syscw: write system calls
};

/// Runs `program` with `arguments` through `sh -c` (`prefix` goes first, e.g. a ulimit);
/// output goes to a file. When `kill_after` is given, the process gets SIGKILL then.
Outcome launch(const std::string& program, const std::string& arguments,
               const std::string& prefix = "",
               std::optional<std::chrono::microseconds> kill_after = std::nullopt) {
  const fs::path output =
      fs::temp_directory_path() / ("sbptt_outputs_" + std::to_string(getpid()) + ".out");
  const std::string command =
      prefix + "exec " + examples_dir() + "/" + program + " " + arguments + " > " +
      output.string() + " 2>&1";
  const pid_t pid = fork();
  REQUIRE(pid >= 0);
  if (pid == 0) {
    execl("/bin/sh", "sh", "-c", command.c_str(), static_cast<char*>(nullptr));
    _exit(127);
  }
  if (kill_after) {
    std::this_thread::sleep_for(*kill_after);
    kill(pid, SIGKILL);
  }
  siginfo_t info{};
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

fs::path scratch(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("sbptt_outputs_" + std::to_string(getpid()));
  fs::create_directories(dir);
  return dir / name;
}

fs::path fresh_dir(const std::string& name) {
  const fs::path dir = scratch(name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

std::string file_text(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), {}};
}

/// The log without its last column (seconds is wall time, the one field that differs).
std::string without_seconds(const std::string& csv) {
  std::string out;
  std::istringstream in(csv);
  for (std::string line; std::getline(in, line);) out += line.substr(0, line.rfind(',')) + "\n";
  return out;
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
  // A file-size limit (SIGXFSZ ignored) fails the log's writes with EFBIG, as a full disk does.
  const fs::path log = scratch("full.csv"), params = scratch("kept.params");
  fs::remove(params);
  const Outcome r = launch("toy", "--epochs 2000 --csv " + log.string() + " --save-params " +
                                      params.string(), "trap '' XFSZ; ulimit -f 16; ");
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
  const fs::path dir = fresh_dir("same");
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

TEST_CASE("a symbolic link as --csv gets its target written", "[programs]") {
  const fs::path dir = fresh_dir("link");
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
  const fs::path params = fresh_dir("mode") / "p.txt";
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

TEST_CASE("killed with SIGKILL at random moments, a rerun with --checkpoint ends bit for bit "
          "as one uninterrupted run", "[programs]") {
  std::mt19937 random(12345);
  for (const std::string variant : {"--method R", "--method C", "--method R --float",
                                    "--method C --float"}) {
    const fs::path dir = fresh_dir("kill");
    const std::string common = "--poles 2 --samples 16 --steps 40 --batch 2 --shuffle --epochs 30 " +
                               variant + " --csv " + (dir / "log.csv").string() +
                               " --save-params " + (dir / "p.txt").string();
    const auto start = std::chrono::steady_clock::now();
    const Outcome whole = launch("cartpole", common);
    const auto duration = std::chrono::steady_clock::now() - start;
    REQUIRE(whole.status == 0);
    const std::string params = file_text(dir / "p.txt"), log = file_text(dir / "log.csv");
    fs::remove(dir / "p.txt");
    fs::remove(dir / "log.csv");

    const std::string resumable = common + " --checkpoint " + (dir / "run.checkpoint").string();
    std::uniform_int_distribution<long> delay(
        10, std::chrono::duration_cast<std::chrono::microseconds>(duration).count() / 3);
    int kills = 0, resumes = 0;
    Outcome last;
    for (int attempt = 0; attempt < 40; ++attempt) {
      const bool kill_it = attempt < 6;  // then let it finish
      last = launch("cartpole", resumable, "",
                    kill_it ? std::optional(std::chrono::microseconds(delay(random)))
                            : std::nullopt);
      resumes += contains(last.output, "resuming after epoch") ? 1 : 0;
      // Nothing half-written is ever left beside the outputs.
      for (const auto& entry : fs::directory_iterator(dir))
        CHECK_FALSE(contains(entry.path().filename().string(), ".tmp."));
      if (last.status == -SIGKILL) ++kills;
      if (last.status == 0) break;
    }
    INFO(variant << ": " << kills << " kills, " << resumes << " resumes\n" << last.output);
    REQUIRE(last.status == 0);
    CHECK(kills >= 2);
    CHECK(resumes >= 1);
    CHECK(file_text(dir / "p.txt") == params);
    CHECK(without_seconds(file_text(dir / "log.csv")) == without_seconds(log));
  }
}
