// reproduce: the figures (tools/plot_results.py) and the printed plan of --dry-run.
#pragma once

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "calibration.hpp"
#include "finished_run.hpp"
#include "options.hpp"
#include "processes.hpp"
#include "run_files.hpp"

namespace reproduce {

/// Draws the figures into <out>/plots. Returns 130 when a signal interrupted the plotting (the
/// figures drawn so far are kept), else 0: a missing script or python is only a warning.
inline int plot(const Options& o, const fs::path& own_dir) {
  std::vector<fs::path> scripts;
  if (!o.plot_script.empty()) scripts.push_back(o.plot_script);
  else
    scripts = {fs::path(__FILE__).parent_path().parent_path().parent_path() / "tools" /
                   "plot_results.py",
               own_dir.parent_path().parent_path() / "tools" / "plot_results.py",
               own_dir / "plot_results.py"};
  const auto script = std::find_if(scripts.begin(), scripts.end(),
                                   [](const fs::path& p) { return fs::is_regular_file(p); });
  if (script == scripts.end()) {
    std::cerr << "reproduce: warning: tools/plot_results.py not found (tried "
              << scripts.front() << "); no plots; pass --plot-script FILE\n";
    return 0;
  }
  std::vector<std::string> pythons;
  if (!o.python.empty()) pythons.push_back(o.python);
  else pythons = {"python3", "/usr/bin/python3"};
  std::string python;
  for (const auto& p : pythons)
    if (run_command({p, "-c", "import matplotlib"}, true) == 0) {
      python = p;
      break;
    }
  if (interrupted) return 130;
  if (python.empty()) {
    std::cerr << "reproduce: warning: no python3 with matplotlib (apt-get install "
                 "python3-matplotlib); no plots\n";
    return 0;
  }
  std::fflush(stdout);
  const fs::path plots = fs::path(o.out) / "plots";
  // The kernel stamps files with a coarse clock, which may lag this one by a tick.
  const auto started = fs::file_time_type::clock::now() - std::chrono::seconds(1);
  const int code =
      run_command({python, path_argument(*script), path_argument(o.out)}, false);
  // A script stopped by a signal cannot clean up after itself: its temporary figures go here.
  std::error_code error;
  for (const auto& entry : fs::directory_iterator(plots, error))
    if (entry.path().filename().string().starts_with(".tmp.")) fs::remove(entry.path(), error);
  // Exit 0 is not yet a figure: a python that is not one (--python /bin/true) exits 0 too,
  // and the figures of an earlier plot may still be there.
  std::size_t figures = 0;
  for (const auto& entry : fs::directory_iterator(plots, error))
    if (entry.is_regular_file(error) && entry.last_write_time(error) >= started) ++figures;
  if (interrupted) {
    std::cerr << "reproduce: interrupted while plotting; "
              << (figures > 0 ? count_of(figures, "figure file") + " drawn in " + plots.string()
                              : std::string("no figure was drawn"))
              << "\n";
    return 130;
  }
  if (code != 0) {
    std::cerr << "reproduce: warning: " << script->string() << " failed (exit code " << code
              << "); no plots\n";
    return 0;
  }
  if (figures == 0)
    std::cerr << "reproduce: warning: " << script->string() << " exited 0 but drew no figure in "
              << plots.string() << "\n";
  else
    std::printf("plots: %s (%zu files drawn)\n", plots.c_str(), figures);
  return 0;
}

/// --dry-run: every planned command, then the estimate from costs measured on this machine
/// with the task programs of `bin_dir` (calibration.hpp). Returns 130 when a signal
/// interrupted the measuring or the printing (which then stops short of the estimate), else 0.
inline int print_plan(const Options& o, const std::vector<Run>& plan, const fs::path& bin_dir) {
  double estimate = 0;
  std::size_t todo = 0;
  const fs::path runs = fs::path(o.out) / "runs";
  // The sweep's own judgement of the files (finished_run.hpp), not their presence: a damaged
  // run is redone, so it counts as work to do.
  const FinishedRuns finished = scan_finished(runs);
  std::vector<Run> unfinished;
  for (const auto& run : plan)
    if (!is_finished(finished, run)) unfinished.push_back(run);
  const std::optional<MeasuredCosts> costs = measure_costs(unfinished, bin_dir, o.threads);
  // A signal after the last measurement still counts: its check in time_probe came before.
  if (!costs || interrupted) {
    std::cerr << "reproduce: interrupted while measuring the task programs; no plan printed, "
                 "nothing written\n";
    return 130;
  }
  const auto stopped_printing = [] {
    if (!interrupted) return false;
    std::fflush(stdout);
    std::cerr << "reproduce: interrupted while printing the plan; it is incomplete and no "
                 "estimate was printed\n";
    return true;
  };
  for (const auto& run : plan) {
    if (stopped_printing()) return 130;
    std::string command;
    for (const auto& a : command_line(run, bin_dir, runs, o.threads))
      command += (command.empty() ? "" : " ") + a;
    const bool done = is_finished(finished, run);
    const auto damage = finished.damaged.find(run.name());
    const std::string state = done ? "  (finished)"
                              : damage != finished.damaged.end()
                                  ? concat("  (damaged, to be redone: ", damage->second, ")")
                                  : std::string();
    std::printf("%-34s %s%s\n", run.name().c_str(), command.c_str(), state.c_str());
    if (!done) estimate += costs->seconds(run).value_or(run.estimated_seconds()), ++todo;
  }
  if (stopped_printing()) return 130;
  print_instruction_sets();
  std::printf("%s planned (profile %s, %zu finished, %zu to do), measured estimate %s of "
              "compute, about %s wall time with --jobs %ld\n",
              count_of(plan.size(), "run").c_str(), o.profile.c_str(), plan.size() - todo, todo,
              format_duration(estimate).c_str(),
              format_duration(estimate / static_cast<double>(std::min<std::size_t>(
                                             static_cast<std::size_t>(o.jobs),
                                             std::max<std::size_t>(todo, 1))))
                  .c_str(),
              o.jobs);
  return 0;
}

}  // namespace reproduce
