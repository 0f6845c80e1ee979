// reproduce: the files of one run in <out>/runs and the task program command that writes them.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include <sbptt/core/error.hpp>
#include <sbptt/core/instruction_set.hpp>

#include "grid.hpp"
#include "processes.hpp"

namespace reproduce {

/// The line that goes with every estimate and timing the runner prints: the task programs of
/// --bin-dir may be another build than the runner, so each run's log names its own.
inline void print_instruction_sets() {
  std::printf("reproduce: built for %s; each run's log, runs/<name>.log, names the instruction "
              "set of its task program\n",
              sbptt::instruction_set());
}

/// runs/<name><suffix>: the files of one run.
inline fs::path run_file(const fs::path& runs, const Run& run, const char* suffix) {
  return runs / (run.name() + suffix);
}

/// Throws unless the task program of `run` in `bin_dir` can be executed: an IoError when
/// `bin_dir` is the default (the examples are not built), a bad --bin-dir when it is the
/// user's (`from_flag`).
inline void require_task_program(const Run& run, const fs::path& bin_dir, bool from_flag = false) {
  const fs::path program = bin_dir / run.info().program;
  if (is_executable(program)) return;
  if (from_flag)
    throw InvalidArgument(concat("--bin-dir '", bin_dir.string(), "' holds no executable task ",
                                 "program '", run.info().program, "'; expected the folder of ",
                                 "the built examples (build/examples)"));
  throw sbptt::IoError(concat("no executable task program '", program.string(),
                              "'; build the examples or pass --bin-dir DIR"));
}

/// `path` as another program's argument: a relative path that starts with '-' (--out=--results)
/// would read as a flag there.
inline std::string path_argument(const fs::path& path) {
  return path.string().starts_with('-') ? "./" + path.string() : path.string();
}

/// The task program's command line. --threads is passed here and kept out of Run::flags(),
/// which make the run's .run file: results are bitwise identical for any thread count
/// (docs/benchmarks.md), so a sweep resumed with another --threads keeps its finished runs.
/// A program that supports it gets --checkpoint runs/<name>.checkpoint: killed, the run
/// resumes from its last epoch (the checkpoint holds the log's rows too) under any executor.
inline std::vector<std::string> command_line(const Run& run, const fs::path& bin_dir,
                                             const fs::path& runs, long threads) {
  const fs::path program = bin_dir / run.info().program;
  std::vector<std::string> argv{program.string()};
  for (const auto& f : run.flags()) argv.push_back(f);
  argv.insert(argv.end(), {"--threads", std::to_string(threads), "--csv",
                           path_argument(run_file(runs, run, ".partial.csv"))});
  if (supports_checkpoints(program))
    argv.insert(argv.end(), {"--checkpoint", path_argument(run_file(runs, run, ".checkpoint"))});
  return argv;
}

}  // namespace reproduce
