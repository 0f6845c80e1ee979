// reproduce: when a run counts as finished. A run is finished when runs/<name>.run describes
// it, runs/<name>.log ends with the runner's line "# reproduce: exit code N after ..." with N
// 0 or 3, and runs/<name>.csv is a whole training log that agrees with N: every planned epoch
// after exit code 0, fewer after exit code 3 (a non-finite value stopped the run). Anything
// else (a file missing, emptied or cut by a crash or a user) is damage: the run is redone.
#pragma once

#include <algorithm>
#include <filesystem>
#include <iostream>
#include <map>
#include <optional>
#include <string>
#include <tuple>
#include <vector>

#include <sbptt/core/atomic_file.hpp>
#include <sbptt/core/error.hpp>

#include "grid.hpp"
#include "locks.hpp"
#include "run_files.hpp"
#include "summary.hpp"
#include "text.hpp"

namespace reproduce {

/// The last line the runner writes into a run's log: "# reproduce: exit code N after S s wall
/// time".
inline constexpr const char* exit_line_prefix = "# reproduce: exit code ";

struct ExitLine {
  int code = 0;
  double wall_seconds = 0;  ///< the whole run: start-up, training and evaluation
};

/// The runner's last line of `log`, or nullopt when there is none.
inline std::optional<ExitLine> logged_exit(const fs::path& log) {
  const auto lines = split(read_text(log), '\n');
  for (auto it = lines.rbegin(); it != lines.rend(); ++it) {
    if (it->empty()) continue;
    if (!it->starts_with(exit_line_prefix)) return std::nullopt;
    const auto words = split(it->substr(std::string(exit_line_prefix).size()), ' ');
    try {
      if (words.size() < 3 || words[1] != "after") return std::nullopt;
      return ExitLine{static_cast<int>(parse_integer("exit code", words[0], 0, 255)),
                      parse_number("wall time", words[2], 0, 1e12)};
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
  double wall_seconds = 0;
};

/// Checks the files of `run` in `runs` (its .csv exists) against each other.
inline FinishedRun check_finished(const Run& run, const fs::path& runs) {
  const fs::path description = run_file(runs, run, ".run");
  const fs::path log = run_file(runs, run, ".log");
  if (!fs::exists(description)) return {{}, "its .run file is missing"};
  if (read_text(description) != run.description())
    return {{}, "its .run file does not describe it (damaged)"};
  if (!fs::exists(log)) return {{}, concat("its log ", log.string(), " is missing")};
  const auto exit = logged_exit(log);
  if (!exit) return {{}, concat("its log ", log.string(), " has no exit code line (cut)")};
  try {
    Summary summary = summarize(run, run_file(runs, run, ".csv"));
    std::string why = contradiction(summary, exit->code);
    if (!why.empty()) return {{}, concat(why, " (the log contradicts it)")};
    return {std::move(summary), {}, exit->wall_seconds};
  } catch (const sbptt::ParseError& e) {
    return {{}, concat(e.what(), " (damaged)")};
  }
}

/// What the runs folder holds: the finished runs (of any sweep), the damaged ones, and the
/// measured cost of the runs, for the time estimates.
struct FinishedRuns {
  std::map<decltype(Run{}.order_key()), Summary> summaries;
  std::map<std::string, std::string> damaged;  ///< run name -> why it cannot be trusted
  /// Wall seconds per (epoch · train sample) of the complete runs, by task, method, precision.
  std::map<std::tuple<int, Method, bool>, std::vector<double>> cost;

  /// The expected wall time of `run`: the median measured cost of its task, method and
  /// precision when a complete run of them is finished, else the built-in estimate.
  [[nodiscard]] double expected_seconds(const Run& run) const {
    const auto found = cost.find({run.task, run.method, run.use_float});
    if (found == cost.end()) return run.estimated_seconds();
    std::vector<double> rates = found->second;
    std::nth_element(rates.begin(), rates.begin() + static_cast<long>(rates.size() / 2),
                     rates.end());
    return rates[rates.size() / 2] * static_cast<double>(run.epochs) *
           static_cast<double>(run.samples);
  }
};

/// Checks every runs/<name>.csv (not the partial ones, nor a file whose name is no run's).
inline FinishedRuns scan_finished(const fs::path& runs) {
  FinishedRuns found;
  std::error_code error;
  for (const auto& entry : fs::directory_iterator(runs, error)) {
    const fs::path path = entry.path();
    const std::string name = path.stem().string();
    if (path.extension() != ".csv" || name.ends_with(".partial") || !is_run_name(name))
      continue;
    const auto run = parse_description(read_text(fs::path(path).replace_extension(".run")));
    FinishedRun finished = run && run->name() == name
                               ? check_finished(*run, runs)
                               : FinishedRun{{}, "its .run file is missing or damaged", 0};
    if (!finished.summary) {
      found.damaged[name] = finished.damage;
      continue;
    }
    const Summary& s = *finished.summary;
    if (s.status() == "ok")
      found.cost[{run->task, run->method, run->use_float}].push_back(
          finished.wall_seconds / static_cast<double>(run->epochs * run->samples));
    found.summaries[run->order_key()] = std::move(*finished.summary);
  }
  return found;
}

/// Says on stderr that the run `name`, which the current plan does not hold, is damaged and
/// in no summary; `then` is what becomes of its files.
inline void warn_unplanned_damage(const std::string& name, const std::string& why,
                                  const std::string& then) {
  std::cerr << "reproduce: warning: " << name << " (not planned now): " << why
            << "; left out of summary.csv" << then << "\n";
}

/// A folder in `runs` under a name the runner keeps a run's file by (runs/<name>.csv, a
/// temporary), or nothing. The runner removes and replaces such files; it removes no folder,
/// since one holds what a user put there, so every mode refuses one before any work.
inline std::optional<fs::path> folder_among_run_files(const fs::path& runs) {
  if (!fs::is_directory(runs)) return std::nullopt;
  for (const auto& entry : fs::directory_iterator(runs)) {
    if (!entry.is_directory()) continue;
    const std::string file = entry.path().filename().string();
    for (const std::string_view suffix : {".csv", ".log", ".run", ".lock", ".checkpoint"})
      if (file.ends_with(suffix)) return entry.path();
    for (const std::string_view infix : {".partial.", ".tmp."})
      if (file.find(infix) != std::string::npos) return entry.path();
  }
  return std::nullopt;
}

/// Removes `file` if it is there, and whether it went. One that cannot go (made immutable,
/// another user's in a shared folder) is named in a warning: thrown, it stopped every executor
/// in the folder, unrelated runs too.
inline bool remove_or_warn(const fs::path& file) {
  std::error_code error;
  const bool removed = fs::remove(file, error);
  if (error)
    std::cerr << "reproduce: warning: cannot remove " << file << ": " << error.message()
              << "; remove it by hand\n";
  return removed;
}

/// Moves the finished-run files of the damaged run `name` into a folder of their own,
/// runs/damaged/<name>.<k> with the first free k (two damages of one run never mix or
/// overwrite each other), and removes its checkpoint. Moved, not removed: what made them
/// damaged may be a blank line an editor added or a copy's CRLF, and the rows are the user's
/// work. Where no such folder can be made, each file is renamed to <file>.damaged beside it
/// (over an earlier one): runs/<name>.csv must go, as it marks the run finished. Returns
/// where they went, for a message.
inline std::string set_aside_damaged(const fs::path& runs, const std::string& name) {
  std::error_code error;
  const fs::path damaged = runs / "damaged";
  fs::create_directories(damaged, error);
  fs::path aside;
  for (int k = 1; !error && aside.empty() && k <= 10'000; ++k)
    if (fs::create_directory(damaged / concat(name, ".", k), error))
      aside = damaged / concat(name, ".", k);
  for (const char* suffix : {".checkpoint", ".checkpoint.lock"})
    remove_or_warn(runs / (name + suffix));
  std::string kept = aside.empty()
                         ? concat("its files renamed to ", (runs / name).string(),
                                  ".*.damaged (no folder for them in ", damaged.string(),
                                  error ? ": " + error.message() : std::string(), ")")
                         : concat("its files moved to ", aside.string());
  for (const char* suffix : {".csv", ".log", ".run"}) {
    const fs::path file = runs / (name + suffix);
    if (!fs::exists(fs::symlink_status(file, error))) continue;
    fs::rename(file, aside.empty() ? fs::path(file.string() + ".damaged") : aside / file.filename(),
               error);
    if (error && remove_or_warn(file))
      kept += concat(" (but ", file.string(), ", which could not be moved: ", error.message(),
                     ", was removed)");
  }
  return kept;
}

/// Rewrites <out>/summary.csv from every finished run on disk, under <out>/.lock, so that
/// executors sharing the folder add their runs one after the other; returns what it found.
inline FinishedRuns rebuild_summary(const fs::path& out) {
  const FileLock lock = lock_summary(out);
  FinishedRuns finished = scan_finished(out / "runs");
  for (const auto& entry : fs::directory_iterator(out))
    if (entry.path().filename().string().starts_with("summary.csv.tmp."))
      remove_or_warn(entry.path());  // of a writer killed while it held the lock
  std::vector<Summary> rows;
  for (const auto& [key, s] : finished.summaries) rows.push_back(s);
  sbptt::write_file_atomically((out / "summary.csv").string(), summary_csv(rows));
  return finished;
}

/// The planned runs whose finished files in `runs` describe the same run with other settings
/// (other epochs, a retuned profile). Every mode refuses them before any work: a sweep would
/// have to overwrite them, and --dry-run, --merge and --emit would count them as done.
inline std::vector<std::string> runs_of_other_settings(const fs::path& runs,
                                                       const std::vector<Run>& plan) {
  std::vector<std::string> mismatched;
  for (const Run& run : plan) {
    if (!fs::exists(run_file(runs, run, ".csv"))) continue;
    const auto described = parse_description(read_text(run_file(runs, run, ".run")));
    if (described && described->name() == run.name() &&
        described->description() != run.description())
      mismatched.push_back(run.name());
  }
  return mismatched;
}

/// Says on stderr which finished runs were made with other settings than planned now, and
/// what the user can do; `during` when another executor made them while this one ran.
inline void report_other_settings(const fs::path& runs, const std::vector<std::string>& mismatched,
                                  bool during) {
  std::cerr << "reproduce: " << count_of(mismatched.size(), "finished run") << " in " << runs
            << (mismatched.size() == 1 ? " was" : " were")
            << " made with other settings than planned now"
            << (during ? ", by another executor during this sweep" : "") << " (e.g. "
            << mismatched[0] << ": see its .run file); "
            << (during ? "two sweeps of other settings share this --out: choose another --out "
                         "for one of them, or remove runs/<name>.* to redo those runs"
                       : "rerun with the old settings, choose another --out, or remove "
                         "runs/<name>.* to redo them")
            << "\n";
}

/// Whether `run` is among the finished runs (its name, not only its grid position).
inline bool is_finished(const FinishedRuns& finished, const Run& run) {
  const auto found = finished.summaries.find(run.order_key());
  return found != finished.summaries.end() && found->second.run.name() == run.name();
}

}  // namespace reproduce
