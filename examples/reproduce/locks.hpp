// reproduce: the locks that let several executors (a --jobs pool, shards, GNU parallel, Slurm
// array tasks) share one output folder. runs/<name>.lock is held (flock, exclusive) by the
// one process that runs or cleans up that run; <out>/.lock is held briefly by whoever rewrites
// summary.csv. flock locks die with their process, so a SIGKILLed executor leaves none held.
#pragma once

#include <filesystem>
#include <string>

#include <sbptt/core/file_lock.hpp>

#include "text.hpp"

namespace reproduce {

using sbptt::detail::FileLock;

/// runs/<name>.lock: held while a process runs the run or removes its partial files.
inline FileLock try_lock_run(const fs::path& runs, const std::string& name) {
  return FileLock::take(runs / (name + ".lock"), false);
}

/// Whether another process holds the run's lock now (it is running the run). On a file system
/// without locks no lock is held, and a lock file only tells that a run once started.
inline bool run_is_locked(const fs::path& runs, const std::string& name) {
  if (!fs::exists(runs / (name + ".lock"))) return false;
  return try_lock_run(runs, name).busy();
}

/// <out>/.lock: held while summary.csv is rebuilt, so that concurrent executors write it one
/// after the other, each from the files on disk.
inline FileLock lock_summary(const fs::path& out) { return FileLock::take(out / ".lock", true); }

}  // namespace reproduce
