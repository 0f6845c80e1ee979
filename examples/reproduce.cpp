// The reproduction runner (docs/reproduce.md): computes the plan of the paper's grid of task ×
// complexity × method × clip mode × seed, runs it as child processes of the task programs
// (--jobs), or hands it to GNU parallel (--emit parallel), Slurm (--emit slurm) or any other
// scheduler (--shard K/N, --run NAME), and collects the results into <out>/summary.csv, a
// results table and the plots (at the end, or with --merge).
//
//   reproduce --profile quick                       # all three tasks, about 10 min on 2 cores
//   reproduce --profile paper --seeds 3 --jobs 8    # the published settings
//   reproduce --profile paper --tasks cartpole --complexities 4 --methods R,C --dry-run
//
// Resume contract: a child writes runs/<name>.partial.csv (and runs/<name>.checkpoint when the
// program keeps checkpoints) and its output goes to runs/<name>.partial.log; when it exits 0
// (or 3: a non-finite value stopped training, a result in itself) the runner checks the log,
// fsyncs and renames the files to runs/<name>.log and runs/<name>.csv. A run is finished only
// when its files hold together (finished_run.hpp); anything else is redone, from its checkpoint
// when it has one. runs/<name>.lock is held by whoever runs the run. Children die with the
// runner (PR_SET_PDEATHSIG), even when it is SIGKILLed.
//
// The parts, one concern each, in examples/reproduce/:
//   grid and profiles     grid.hpp (tasks, profiles, the identity of a run), options.hpp
//                         (command line, plan, shards)
//   run identity, resume  run_files.hpp (a run's files and command), finished_run.hpp (when a
//                         run counts as finished), durable_files.hpp (fsync), locks.hpp
//   executors             local_executor.hpp (the --jobs pool), processes.hpp (children,
//                         signals), emit.hpp (GNU parallel, Slurm)
//   summary and merge     summary.hpp (summary.csv, results table), merge.hpp (--merge),
//                         plot.hpp (figures, --dry-run plan)
//
// Exit codes: 0 every planned run finished, 1 a run failed or an error (--merge: runs missing),
// 2 bad flags, 130 interrupted (SIGINT/SIGTERM/SIGHUP, also while plotting or while --dry-run
// measures or prints; the finished runs are kept).

#include <exception>
#include <iostream>

#include "reproduce/emit.hpp"
#include "standard_streams.hpp"
#include "reproduce/local_executor.hpp"
#include "reproduce/merge.hpp"
#include "reproduce/options.hpp"
#include "reproduce/plot.hpp"

using namespace reproduce;  // NOLINT(google-build-using-namespace): the program's own namespace
namespace fs = std::filesystem;

namespace {

int run_reproduce(int argc, char** argv) {
  Options options;
  std::vector<Run> plan;
  const fs::path self = own_executable(argv[0]);
  const fs::path own_dir = self.parent_path();
  fs::path bin_dir;
  try {
    options = parse_options(argc, argv);
    if (options.help) return 0;  // parse_options printed it
    if (!options.python.empty() && !can_execute(options.python))
      throw InvalidArgument(concat("--python '", options.python, "' is no executable program; "
                                   "expected a path or a name on PATH"));
    std::error_code error;  // a path the system cannot even look at is no file either
    // --emit slurm hands it to the merge job, which would fail on it after the whole array.
    if (options.plot && !options.dry_run && options.emit != "parallel" &&
        !options.plot_script.empty() && !fs::is_regular_file(options.plot_script, error))
      throw InvalidArgument(concat("--plot-script '", options.plot_script, "' is no file; "
                                   "expected the plotting script (tools/plot_results.py)"));
    bin_dir = options.bin_dir.empty() ? own_dir : fs::path(options.bin_dir);
    if (options.emit == "slurm") require_slurm_folder(options);
    if (options.emit == "parallel") require_one_line_paths(options, self, bin_dir);
    plan = make_plan(options);
    if (plan.empty())
      throw InvalidArgument(concat(
          "--profile ", options.profile, " has no run of the --tasks, --methods, --clips and "
          "--complexities given; expected a selection the profile has (--dry-run without them "
          "lists its runs; the cart chain is in --profile reviewers alone)"));
    // --merge accounts for the whole plan; everything else works on this process's share.
    if (!options.merge) plan = select_share(options, plan);
    // Every mode but --merge runs the task programs or hands out their commands.
    if (!options.bin_dir.empty() && !options.merge)
      for (const auto& run : plan) require_task_program(run, options.bin_dir, true);
  } catch (const InvalidArgument& e) {
    std::cerr << "reproduce: " << e.what() << "\n";
    return 2;
  }
  try {
    const fs::path runs = fs::path(options.out) / "runs";
    if (const auto mismatched = runs_of_other_settings(runs, plan); !mismatched.empty()) {
      report_other_settings(runs, mismatched, false);
      return 1;
    }
    if (const auto folder = folder_among_run_files(runs)) {
      std::cerr << "reproduce: '" << folder->string()
                << "' is a folder where the runner keeps a run's file; it removes files only: "
                   "move the folder away, then run again\n";
      return 1;
    }
    if (options.dry_run) {
      install_signal_handlers();
      return print_plan(options, plan, bin_dir);
    }
    if (options.emit == "parallel") return emit_parallel(options, plan, self, bin_dir);
    if (options.emit == "slurm") return emit_slurm(options, plan, self, bin_dir);
    if (options.merge) {
      install_signal_handlers();
      const int code = merge(options, plan);
      if (options.plot && plot(options, own_dir) == 130) return 130;
      return code;
    }
    for (const auto& run : plan) require_task_program(run, bin_dir);
    install_signal_handlers();
    Sweep sweep(options, plan, bin_dir);
    const int code = sweep.execute();
    if (code == 130) return code;
    if (options.plot && plot(options, own_dir) == 130) return 130;
    return code;
  } catch (const std::exception& e) {
    std::cerr << "reproduce: " << e.what() << "\n";
    return 1;
  }
}

}  // namespace

// What reproduce prints is part of its work (the commands of --emit parallel, the plan, the
// table): a write that failed turns exit 0 into 1.
int main(int argc, char** argv) {
  return sbptt::examples::with_streams_checked("reproduce", run_reproduce(argc, argv));
}
