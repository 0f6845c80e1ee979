// reproduce: --merge, the collecting end of any executor. It rebuilds summary.csv from every
// finished run in the output folder, prints the results table, and counts the planned runs as
// done, running (another process holds the run's lock) or missing, listing the missing ones.
#pragma once

#include <cstdio>
#include <filesystem>
#include <set>
#include <string>
#include <vector>

#include "finished_run.hpp"
#include "locks.hpp"
#include "options.hpp"
#include "summary.hpp"

namespace reproduce {

/// Returns 0 when every planned run is done, else 1.
inline int merge(const Options& o, const std::vector<Run>& plan) {
  const fs::path out = o.out;
  fs::create_directories(out / "runs");
  const FinishedRuns finished = rebuild_summary(out);
  std::vector<Summary> rows;
  for (const auto& [key, s] : finished.summaries) rows.push_back(s);
  print_table(rows);
  std::printf("\nsummary: %s\n", (out / "summary.csv").c_str());
  std::size_t done = 0;
  std::vector<std::string> running, missing;
  for (const auto& run : plan) {
    if (is_finished(finished, run)) ++done;
    else if (run_is_locked(out / "runs", run.name())) running.push_back(run.name());
    else missing.push_back(run.name());
  }
  std::printf("reproduce: merge: %zu of %zu planned runs done, %zu running (lock held), %zu "
              "missing\n",
              done, plan.size(), running.size(), missing.size());
  for (const auto& name : running) std::printf("  running: %s\n", name.c_str());
  for (const auto& name : missing) {
    const auto damaged = finished.damaged.find(name);
    if (damaged == finished.damaged.end()) {
      std::printf("  missing: %s\n", name.c_str());
    } else {
      std::printf("  damaged: %s: %s\n", name.c_str(), damaged->second.c_str());
    }
  }
  std::set<std::string> planned;
  for (const Run& run : plan) planned.insert(run.name());
  for (const auto& [name, why] : finished.damaged)
    if (!planned.contains(name))
      warn_unplanned_damage(name, why, "; a sweep that plans it redoes it");
  return running.empty() && missing.empty() ? 0 : 1;
}

}  // namespace reproduce
