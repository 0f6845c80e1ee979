// Speed of one training epoch at the paper's settings, against the machine's own peak.
//
// One row per task × method × scalar: cart pole (1 and 4 poles, MLP 2×100 tanh), guidance
// (2 drivers, 4 evaders, MLP 2×100 tanh, rc = 0.1) and quantum control (target n = 4, the
// paper's "target state 3"; the paper's CNN), methods R, M, C, S, in float and double. An
// epoch is exactly `Trainer::train_epoch`: 256 training samples in batches of 8 (32 Adam
// updates, lr 1e-3) over the full horizon, then the evaluation of the 256-sample train and
// test sets. Extra rows (quantum, R, float) repeat the epoch on finer grids, Nx = 64, 128,
// 256, with the CNN widened to match, to show that the simulator's work grows linearly in Nx.
// Rows cartpole4-auto, cartpole4-ode, guidance-auto and guidance-ode build the same scenes
// through AutoDiffSimulator and through Integrated (examples/common/scene_routes.hpp), to price
// automatic derivatives against the hand-written ones.
//
// Columns:
//   ms/epoch     best of --repeats timed epochs (after one warm-up epoch), 1 thread; a C row
//                also times the R epoch in turn with its own (CSV ms_epoch_regular_in_turn),
//                and the C/R verdict is the ratio of those two
//   GFLOP        network work of the epoch: the dense/conv multiply-adds of every forward,
//                parameter-VJP and input-VJP call the engine made (counted at the call, 2 flops
//                per multiply-add)
//   GFLOP/s      GFLOP / time
//   peak, %peak  the row's peak GFLOP/s (an n×n Eigen matrix product on one core, same
//                scalar, best of several sizes, timed in turn with the row's epochs so that
//                both see the same minute), and GFLOP/s over it
//   ms Nt, xNt   the same epoch with --threads N threads, and the speed-up over 1 thread
//                (the 1- and N-thread epochs timed in turn, so that both see the same minute)
//   rt ns        right after those epochs, the round trip of a cache line between two
//                threads (bench/rows.hpp): the machine's cost of a hand-off, which varies
//                (docs/benchmark-runs.md, eleventh run); "-" with one thread. The
//                two-thread verdicts add how much slower the main thread reads lines the
//                other core wrote than its own (about 1: the cores share their last-level
//                cache; CSV other_core_read_ratio) and how many times as long two 1-thread
//                epochs take when run at once, each on its own thread, as one alone (CSV
//                copies_ratio): what the host gives two busy cores, so that a two-thread
//                speed-up above 2 / that ratio cannot be had here; and the speed-ups of
//                the epoch's two parts, the evaluation of the two sets (timed alone, in
//                turn: CSV ms_evaluation, ms_evaluation_threads) and its training batches
//                (the rest of the epoch), with how many of the N-thread trainer's sweeps
//                whose threads meet at every step ran on the threads (CSV sweeps_threaded,
//                sweeps_alone; the rest ran on one thread: `SweepThreading` in the engine);
//                then the speed-up of the epoch of a run that evaluates it on a second
//                thread while the next epoch trains on the first (`evaluate_beside` of
//                `run_training`), against the same uncounted trainer's 1-thread epoch (CSV
//                ms_epoch_beside, ms_epoch_beside_alone), and its bound, epoch / training
//                batches
//   sim ns       one simulator step plus one full VJP (Aᵀλ and Bᵀλ) per sample, on the
//                states of the last training batch (the per-sample work of the engine;
//                for a BatchSimulator, the batched calls' time over the batch size)
//   traj KiB     the stored trajectory of one batch of 8 (states, controls, network workspace)
//   RSS MiB      peak resident memory (getrusage ru_maxrss) of a process that ran the row
//
// Every row runs in its own child process, so that its RSS is its own.
//
// The parts: bench/rows.hpp (what a row measures, how each task's row is built, the child
// process), bench/counting_network.hpp (the GFLOP count), bench/targets.hpp (the targets, met
// or MISSED, and the CSV); this file keeps the flags and the order of the rows.
//
// Usage: bench [--csv FILE] [--repeats R] [--threads N] [--sweep-threading WAY] [--tasks LIST]
//              [--scalars LIST] [--methods LETTERS]
//   --sweep-threading  timed, always or never: how the N-thread trainer runs a batch
//              whose sweep meets the other thread at every step (`SweepThreading`; default
//              timed; CSV sweep_threading)
//   --tasks    comma list of cartpole1, cartpole4, cartpole4-auto, cartpole4-ode, guidance,
//              guidance-auto, guidance-ode, quantum, quantum-nx (default all)
//   --scalars  comma list of float, double (default both)
//   --methods  letters out of RMCS (default RMCS)
#include <sys/resource.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <string>
#include <thread>
#include <vector>

#include <sbptt/sbptt.hpp>

#include "bench/rows.hpp"
#include "bench/targets.hpp"
#include "command_line.hpp"
#include "standard_streams.hpp"

using namespace bench;  // NOLINT(google-build-using-namespace): the program's own namespace

namespace {

std::vector<std::string> split(const std::string& text) {
  std::vector<std::string> parts;
  std::string part;
  for (const char c : text + ",") {
    if (c == ',') {
      if (!part.empty()) parts.push_back(part);
      part.clear();
    } else {
      part += c;
    }
  }
  return parts;
}

/// A comma list of `allowed` words; throws naming `flag` and the unknown word.
std::vector<std::string> parse_list(const std::string& flag, const std::string& text,
                                    const std::vector<std::string>& allowed) {
  std::vector<std::string> values = split(text);
  if (values.empty()) throw sbptt::InvalidArgument(flag + " needs at least one value");
  for (const auto& v : values) {
    if (std::find(allowed.begin(), allowed.end(), v) == allowed.end()) {
      std::string list;
      for (const auto& a : allowed) list += (list.empty() ? "" : ", ") + a;
      throw sbptt::InvalidArgument(flag + " value '" + v + "' is unknown; expected " + list);
    }
  }
  return values;
}

/// Returns false after --help; throws InvalidArgument on a bad flag, IoError on an unwritable
/// --csv (checked now, not after the minutes of measuring).
bool parse(int argc, char** argv, Settings& s) {
  sbptt::examples::CommandLine cli(
      "bench", "Speed of one training epoch at the paper's settings against the machine's own "
               "peak (docs/benchmarks.md). Exit codes: 0 success, 1 error, 2 bad flag.");
  cli.path("--csv", s.csv, "also write the rows as CSV here");
  cli.integer("--repeats", s.repeats, 1, 100, "timed epochs per row (the best is kept)");
  cli.integer("--threads", s.threads, 1, 64, "threads of the threaded column");
  cli.value("--sweep-threading", "WAY",
            "timed, always or never: whether the threaded trainer runs a batch whose sweep meets "
            "the other thread at every step on the threads",
            "timed", [&s](const std::string& text) {
              s.sweep_threading = sbptt::parse_sweep_threading(text);
            });
  cli.value("--tasks", "LIST",
            "comma list of cartpole1, cartpole4, cartpole4-auto, cartpole4-ode, guidance, "
            "guidance-auto, guidance-ode, quantum, quantum-nx",
            "all", [&s](const std::string& text) {
              s.tasks = parse_list("--tasks", text,
                                   {"cartpole1", "cartpole4", "cartpole4-auto", "cartpole4-ode",
                                    "guidance", "guidance-auto", "guidance-ode", "quantum",
                                    "quantum-nx"});
            });
  cli.value("--scalars", "LIST", "comma list of float, double", "float,double",
            [&s](const std::string& text) {
              s.scalars = parse_list("--scalars", text, {"float", "double"});
            });
  cli.value("--methods", "LETTERS", "letters out of RMCS", "RMCS", [&s](const std::string& text) {
    if (text.empty() || text.find_first_not_of("RMCS") != std::string::npos)
      throw sbptt::InvalidArgument("--methods '" + text +
                                   "' is not valid; expected letters out of RMCS");
    s.methods = text;
  });
  return cli.parse(argc, argv);
}

std::string cpu_model() {
  std::ifstream in("/proc/cpuinfo");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("model name", 0) == 0) return line.substr(line.find(':') + 2);
  return "unknown";
}

bool wanted(const Settings& s, const std::string& task) {
  return std::find(s.tasks.begin(), s.tasks.end(), task) != s.tasks.end();
}

}  // namespace

int main(int argc, char** argv) {
  Settings settings;
  try {
    if (!parse(argc, argv, settings)) return sbptt::examples::with_streams_checked("bench", 0);
  } catch (const sbptt::InvalidArgument& e) {
    std::fprintf(stderr, "bench: %s\n", e.what());
    return 2;
  }
  try {
    if (!settings.csv.empty()) sbptt::check_output_path(settings.csv, "--csv");
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench: %s\n", e.what());
    return 1;
  }
  try {
    const std::string way =
        settings.threads > 1 ? "; --sweep-threading " + sbptt::to_string(settings.sweep_threading)
                             : "";
    std::printf("sbptt bench: %s code on %s, %u hardware threads; epoch = Trainer::train_epoch "
                "(256 train in batches of 8, + evaluation of 256 train and 256 test)%s\n",
                sbptt::instruction_set(), cpu_model().c_str(), std::thread::hardware_concurrency(),
                way.c_str());
    const double empty_rss = in_child([] {
      RowResult r;
      rusage usage{};
      getrusage(RUSAGE_SELF, &usage);
      r.rss_kib = static_cast<double>(usage.ru_maxrss);
      return r;
    }).rss_kib;
    std::printf("RSS of an idle child %.1f MiB\n\n", empty_rss / 1024);
    // Its figures are its result: a stdout that fails (a full disk) stops it before minutes of
    // measuring.
    if (!sbptt::examples::streams_written("bench")) return 1;

    struct Job {
      std::string task, scalar;
      char method;
      std::function<RowResult()> run;
    };
    std::vector<Job> jobs;
    const auto add = [&](const std::string& task, auto float_row, auto double_row) {
      if (!wanted(settings, task)) return;
      for (const auto& scalar : settings.scalars) {
        for (const char letter : settings.methods) {
          const Method method = sbptt::parse_method(std::string(1, letter));
          jobs.push_back({task, scalar, letter, [=, &settings] {
                            return scalar == "float" ? float_row(settings, method)
                                                     : double_row(settings, method);
                          }});
        }
      }
    };
    add("cartpole1", cartpole_row<float, 1>, cartpole_row<double, 1>);
    add("cartpole4", cartpole_row<float, 4>, cartpole_row<double, 4>);
    add("cartpole4-auto", cartpole_row<float, 4, Route::Automatic>,
        cartpole_row<double, 4, Route::Automatic>);
    add("cartpole4-ode", cartpole_row<float, 4, Route::Integrated>,
        cartpole_row<double, 4, Route::Integrated>);
    add("guidance", guidance_row<float>, guidance_row<double>);
    add("guidance-auto", guidance_row<float, Route::Automatic>,
        guidance_row<double, Route::Automatic>);
    add("guidance-ode", guidance_row<float, Route::Integrated>,
        guidance_row<double, Route::Integrated>);
    add("quantum", quantum_row<float, 32>, quantum_row<double, 32>);
    const bool float_r = settings.methods.find('R') != std::string::npos &&
                         std::find(settings.scalars.begin(), settings.scalars.end(), "float") !=
                             settings.scalars.end();
    if (wanted(settings, "quantum-nx") && float_r) {
      // Finer grids, R in float only, one timed epoch each: they show the growth in Nx.
      Settings once = settings;
      once.repeats = 1;
      jobs.push_back({"quantum", "float", 'R',
                      [once] { return quantum_row<float, 64>(once, Method::Regular); }});
      jobs.push_back({"quantum", "float", 'R',
                      [once] { return quantum_row<float, 128>(once, Method::Regular); }});
      jobs.push_back({"quantum", "float", 'R',
                      [once] { return quantum_row<float, 256>(once, Method::Regular); }});
    }

    std::printf("%-14s %-6s %-1s %4s %5s %6s %9s %7s %7s %6s %6s %9s %5s %6s %8s %8s %7s\n",
                "task", "scalar", "m", "Nx", "steps", "params", "ms/epoch", "GFLOP", "GFLOP/s",
                "peak", "%peak", ("ms " + std::to_string(settings.threads) + "t").c_str(),
                ("x" + std::to_string(settings.threads) + "t").c_str(), "rt ns", "sim ns",
                "trajKiB", "RSS MiB");
    std::vector<Row> rows;
    // The CSV is rewritten after every row: a signal in the minutes of measuring loses the row
    // under way, not those measured.
    const auto keep = [&](const Row& row) {
      rows.push_back(row);
      if (!settings.csv.empty()) write_csv(settings, rows);
    };
    for (const auto& job : jobs) {
      Row row{job.task, job.scalar, std::string(1, job.method), in_child(job.run)};
      const RowResult& r = row.result;
      if (r.ok == 0) {
        std::printf("%-14s %-6s %-1s failed: %s\n", job.task.c_str(), job.scalar.c_str(),
                    row.method.c_str(), r.error);
        keep(row);
        continue;
      }
      const std::string round_trip =
          r.round_trip_ns > 0 ? std::to_string(std::lround(r.round_trip_ns)) : "-";
      std::printf("%-14s %-6s %-1s %4lld %5lld %6lld %9.1f %7.3f %7.2f %6.1f %5.1f%% %9.1f "
                  "%5.2f %6s %8.0f %8.0f %7.1f\n",
                  job.task.c_str(), job.scalar.c_str(), row.method.c_str(), r.nx, r.steps,
                  r.params, r.ms_epoch, r.gflop, r.gflops(), r.peak_gflops,
                  100 * r.fraction_of_peak(), r.ms_threads,
                  r.ms_epoch / r.ms_threads, round_trip.c_str(), r.sim_ns,
                  r.trajectory_bytes / 1024, r.rss_kib / 1024);
      if (!sbptt::examples::streams_written("bench")) return 1;
      keep(row);
    }
    summarize(rows, settings.threads);
    return sbptt::examples::with_streams_checked("bench", 0);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench: %s\n", e.what());
    return 1;
  }
}
