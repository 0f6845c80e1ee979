#pragma once
// The cost of a planned run, measured on this machine with the task programs of --bin-dir:
// what `--dry-run` estimates the plan from. For every task of the plan, and for R and C, the
// task program runs 1 and then 3 epochs of that task's hardest planned setting (its flags,
// with --epochs changed and at most 256 samples); the difference of the two wall times is two
// epochs including the evaluation of the train and test sets, and what the 1-epoch run
// spends besides its epoch is the start-up (data generation, initial evaluation). M costs what
// R costs and S 0.95 of it (no sweep through time, the evaluation dominates). Costs are taken
// per (epoch · train sample) and do not depend on the complexity (poles, rc, target change
// the network's input size at most).
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <sbptt/core/number_text.hpp>

#include "grid.hpp"
#include "processes.hpp"
#include "run_files.hpp"

namespace reproduce {

/// Measured cost of the runs of one task.
struct TaskCost {
  double regular = 0;   ///< seconds per (epoch · train sample), method R
  double combined = 0;  ///< the same for C
  double start_up = 0;  ///< seconds of a run besides its epochs
};

/// Measured costs per task (empty for a task the plan does not run).
struct MeasuredCosts {
  std::array<std::optional<TaskCost>, task_count> tasks;

  /// Seconds of `run`, or nothing when its task was not measured.
  [[nodiscard]] std::optional<double> seconds(const Run& run) const {
    const auto& cost = tasks[static_cast<std::size_t>(run.task)];
    if (!cost) return std::nullopt;
    double per = cost->regular;
    if (run.method == Method::Combined) per = cost->combined;
    if (run.method == Method::Stopped) per = 0.95 * cost->regular;
    return per * static_cast<double>(run.epochs) * static_cast<double>(run.samples) +
           cost->start_up;
  }
};

/// The scratch folder of `measure_costs` in the temporary directory is this and its pid.
inline constexpr std::string_view probe_folder_prefix = "sbptt-reproduce-probe-";

/// Removes the scratch folders that measurements killed by SIGKILL (which runs no handler)
/// left in `temp`: those named after a process that no longer exists.
inline void remove_killed_probes(const fs::path& temp) {
  std::error_code error;
  for (fs::directory_iterator it(temp, error), end; !error && it != end; it.increment(error)) {
    const std::string name = it->path().filename().string();
    if (!name.starts_with(probe_folder_prefix)) continue;
    const std::string pid = name.substr(probe_folder_prefix.size());
    if (pid.empty() || pid.size() > 9 || pid.find_first_not_of("0123456789") != std::string::npos)
      continue;
    if (::kill(static_cast<pid_t>(std::stol(pid)), 0) == 0 || errno != ESRCH) continue;
    std::error_code not_removed;
    fs::remove_all(it->path(), not_removed);
    if (!not_removed)
      std::printf("reproduce: removed '%s', left by a --dry-run that was killed\n",
                  it->path().c_str());
  }
}

/// The folder of the measurements' scratch folders: TMPDIR, or /tmp where it is unset or empty
/// (as POSIX reads it). Throws `IoError` when TMPDIR names no folder: made here, it would be
/// left behind.
inline fs::path temporary_folder() {
  const char* set = std::getenv("TMPDIR");
  if (set == nullptr || *set == '\0') return "/tmp";
  std::error_code error;
  if (!fs::is_directory(set, error))
    throw sbptt::IoError(concat("TMPDIR '", sbptt::detail::printable(set, 200), "' is no folder",
                                error ? " (" + error.message() + ")" : std::string(),
                                "; expected the folder for --dry-run's scratch files (or TMPDIR "
                                "unset, for /tmp)"));
  return set;
}

/// Wall seconds of `probe` run for `epochs` epochs (stdout and stderr discarded; its training
/// log goes to `scratch`/runs/), or nothing when a signal interrupted it.
inline std::optional<double> time_probe(Run probe, long epochs, const fs::path& bin_dir,
                                        long threads, const fs::path& scratch) {
  probe.epochs = epochs;
  const std::vector<std::string> argv = command_line(probe, bin_dir, scratch / "runs", threads);
  const auto start = std::chrono::steady_clock::now();
  const int code = run_command(argv, true);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (interrupted) return std::nullopt;
  if (code != 0)
    throw sbptt::IoError(concat("measuring ", probe.name(), ": ", argv.front(),
                                " exited with ", code, "; expected a working task program"));
  return seconds;
}

/// Measures every task of `plan` (see the file comment); prints one line per measurement.
/// Nothing when a signal (install_signal_handlers) interrupted it; its scratch folder is gone
/// either way.
inline std::optional<MeasuredCosts> measure_costs(const std::vector<Run>& plan,
                                                  const fs::path& bin_dir, long threads) {
  MeasuredCosts costs;
  const fs::path temp = temporary_folder();
  remove_killed_probes(temp);
  const fs::path scratch = temp / concat(probe_folder_prefix, ::getpid());
  std::error_code error;
  fs::create_directories(scratch / "runs", error);
  if (error)
    throw sbptt::IoError(concat("--dry-run measures the task programs in a scratch folder in '",
                                temp.string(), "' (TMPDIR, else /tmp), which could not be made: ",
                                error.message(), "; expected a writable folder there"));
  struct Cleanup {
    fs::path path;
    ~Cleanup() {
      std::error_code ignored;
      fs::remove_all(path, ignored);
    }
  } cleanup{scratch};
  for (int t = 0; t < task_count; ++t) {
    const Run* hardest = nullptr;
    for (const auto& run : plan)
      if (run.task == t && (hardest == nullptr || run.order_key() > hardest->order_key()))
        hardest = &run;
    if (hardest == nullptr) continue;
    require_task_program(*hardest, bin_dir);
    TaskCost cost;
    for (const Method method : {Method::Regular, Method::Combined}) {
      Run probe = *hardest;
      probe.method = method;
      probe.samples = std::clamp(probe.samples, 8L, 256L);
      const auto one = time_probe(probe, 1, bin_dir, threads, scratch);
      const auto three = one ? time_probe(probe, 3, bin_dir, threads, scratch) : std::nullopt;
      if (!three) return std::nullopt;
      const double epoch = std::max(*three - *one, 1e-6) / 2;
      (method == Method::Regular ? cost.regular : cost.combined) =
          epoch / static_cast<double>(probe.samples);
      if (method == Method::Regular) cost.start_up = std::max(*one - epoch, 0.0);
      std::printf("reproduce: measured %s %s at %ld samples: %.3f s per epoch\n",
                  probe.info().name, std::string(sbptt::label(method)).c_str(), probe.samples,
                  epoch);
      std::fflush(stdout);
    }
    costs.tasks[static_cast<std::size_t>(t)] = cost;
  }
  return costs;
}

}  // namespace reproduce
