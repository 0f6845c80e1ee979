// reproduce: when a run counts as finished. A run is finished when runs/<name>.run describes
// it, runs/<name>.log ends with the runner's line "# reproduce: exit code N after ..." with N
// 0 or 3, and runs/<name>.csv is a whole training log that agrees with N: every planned epoch
// after exit code 0, fewer after exit code 3 (a non-finite value stopped the run). Anything
// else (a file missing, emptied or cut by a crash or a user) is damage: the run is redone.
#pragma once

#include <filesystem>
#include <optional>
#include <string>

#include <sbptt/core/error.hpp>

#include "grid.hpp"
#include "run_files.hpp"
#include "summary.hpp"

namespace reproduce {

/// The last line the runner writes into a run's log; `exit_code` follows it.
inline constexpr const char* exit_line_prefix = "# reproduce: exit code ";

/// The exit code in the runner's last line of `log`, or nullopt when there is none.
inline std::optional<int> logged_exit_code(const fs::path& log) {
  const auto lines = split(read_text(log), '\n');
  for (auto it = lines.rbegin(); it != lines.rend(); ++it) {
    if (it->empty()) continue;
    if (!it->starts_with(exit_line_prefix)) return std::nullopt;
    const std::string rest = it->substr(std::string(exit_line_prefix).size());
    const auto end = rest.find(' ');
    try {
      return static_cast<int>(sbptt::parse_integer("exit code", rest.substr(0, end), 0, 255));
    } catch (const sbptt::Error&) {
      return std::nullopt;
    }
  }
  return std::nullopt;
}

/// Why a training log cannot be the result of a program that exited with `exit_code`, or ""
/// when it can: exit code 0 logs every planned epoch, exit code 3 stopped before the last.
inline std::string contradiction(const Summary& summary, int exit_code) {
  const long planned = summary.run.epochs;
  if (exit_code == 0 && summary.epochs_done != planned)
    return concat("the program exited 0 but its training log has ", summary.epochs_done, " of ",
                  planned, " epochs");
  if (exit_code == 3 && summary.epochs_done >= planned)
    return concat("the program exited 3 (stopped) but its training log has all ", planned,
                  " epochs");
  if (exit_code != 0 && exit_code != 3)
    return concat("its log says the program exited ", exit_code);
  return {};
}

/// A finished run's files, checked: its summary, or why they cannot be trusted.
struct FinishedRun {
  std::optional<Summary> summary;
  std::string damage;  ///< empty when `summary` holds
};

/// Checks the files of `run` in `runs` (its .csv exists) against each other.
inline FinishedRun check_finished(const Run& run, const fs::path& runs) {
  const fs::path description = run_file(runs, run, ".run");
  const fs::path log = run_file(runs, run, ".log");
  if (!fs::exists(description)) return {{}, "its .run file is missing"};
  if (read_text(description) != run.description())
    return {{}, "its .run file does not describe it (damaged)"};
  if (!fs::exists(log)) return {{}, concat("its log ", log.string(), " is missing")};
  const auto code = logged_exit_code(log);
  if (!code) return {{}, concat("its log ", log.string(), " has no exit code line (cut)")};
  try {
    Summary summary = summarize(run, run_file(runs, run, ".csv"));
    std::string why = contradiction(summary, *code);
    if (!why.empty()) return {{}, concat(why, " (the log contradicts it)")};
    return {std::move(summary), {}};
  } catch (const sbptt::ParseError& e) {
    return {{}, concat(e.what(), " (damaged)")};
  }
}

/// Removes the finished-run files of the run `name` so that a sweep that plans it redoes it.
inline void forget_finished(const fs::path& runs, const std::string& name) {
  for (const char* suffix : {".csv", ".log", ".run"}) fs::remove(runs / (name + suffix));
}

}  // namespace reproduce
