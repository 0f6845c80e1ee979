// reproduce: the tasks, the profiles (retune the quick profile here) and the identity of one
// run of the grid: its name, its flags and its runs/<name>.run description.
#pragma once

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <optional>
#include <sstream>
#include <string>
#include <string_view>
#include <system_error>
#include <tuple>
#include <vector>

#include <sbptt/optim/clip.hpp>
#include <sbptt/train/method.hpp>

#include "text.hpp"

namespace reproduce {

using sbptt::ClipMode;
using sbptt::Method;

struct TaskInfo {
  const char* name;              ///< summary label and run-name prefix
  const char* program;           ///< the task program that runs it
  const char* model_flags;       ///< flags that select the task within its program, or ""
  const char* complexity_flag;   ///< the task program's flag for the complexity axis
  const char* complexity_short;  ///< prefix in run names: p4, rc0.001, t4
  const char* complexity_title;  ///< what the complexity is (plots, table)
  bool harder_when_smaller;      ///< guidance: smaller rc is harder
  /// Rough cost of method R: seconds per (epoch · train sample), evaluation of the train and
  /// test sets included, one thread. Only used for the time estimate printed with the plan.
  double seconds_per_sample_epoch;
};

inline constexpr TaskInfo tasks[] = {
    // measured on the 2-core CI machine with --jobs 1 (runs/<name>.log ends with the wall time)
    {"cartpole", "cartpole", "", "--poles", "p", "poles", false, 1.4e-3},
    {"guidance", "guidance", "", "--rc", "rc", "rc", true, 1.0e-3},
    {"quantum", "quantum", "", "--target", "t", "target", false, 9.5e-3},
    // the reviewers' question: links hinged end to end (sim/cart_chain.hpp), not in the paper
    {"chain", "cartpole", "--model chain", "--poles", "n", "links", false, 1.4e-3},
};
inline constexpr int task_count = static_cast<int>(std::size(tasks));

/// Relative cost of a method against R (C runs two reverse sweeps, S none through time).
inline double method_cost(Method m) {
  switch (m) {
    case Method::Regular: return 1.0;
    case Method::Modified: return 1.0;
    case Method::Combined: return 1.25;
    case Method::Stopped: return 0.95;  // the evaluation of train and test sets dominates
    case Method::NetworkOnly: return 1.0;
  }
  return 1.0;
}

/// One task at one complexity: how many seeds, how long.
struct Setting {
  int task;           ///< index into `tasks`
  double complexity;  ///< poles, rc or target
  long seeds;
  long epochs;
  long samples;  ///< train samples (the test set has as many)
};

struct Profile {
  const char* name;
  std::vector<Setting> settings;
  std::vector<Method> methods;
  std::vector<ClipMode> clips;
};

inline constexpr int cartpole = 0, guidance = 1, quantum = 2, chain = 3;
inline constexpr long first_seed = 42;  // the reference's seed; more seeds count up from it

Profile quick_profile() {
  // About 10 minutes with --jobs 2 on 2 cores (retune the epochs/samples columns after
  // measuring; the plan prints its estimate). Three seeds on the hardest setting of each task.
  //          task      complexity seeds epochs samples
  return {"quick",
          {{cartpole, 1, 1, 120, 64},
           {cartpole, 2, 1, 120, 64},
           {cartpole, 3, 1, 120, 64},
           {cartpole, 4, 3, 120, 64},
           {guidance, 1, 1, 120, 64},
           {guidance, 0.1, 1, 120, 64},
           {guidance, 0.01, 1, 120, 64},
           {guidance, 0.001, 3, 120, 64},
           {quantum, 2, 1, 50, 32},
           {quantum, 3, 1, 50, 32},
           {quantum, 4, 3, 50, 32}},
          {Method::Regular, Method::Modified, Method::Combined, Method::Stopped},
          {ClipMode::Norm}};
}

Profile paper_profile() {
  // The published grids (docs/paper.md §4–§6): 1000 epochs, 256 + 256 samples, one seed each.
  std::vector<Setting> s;
  for (double poles : {1, 2, 3, 4}) s.push_back({cartpole, poles, 1, 1000, 256});
  for (double rc : {1.0, 0.1, 0.01, 0.001}) s.push_back({guidance, rc, 1, 1000, 256});
  for (double target : {2, 3, 4}) s.push_back({quantum, target, 1, 1000, 256});
  return {"paper",
          std::move(s),
          {Method::Regular, Method::Modified, Method::Combined, Method::Stopped},
          {ClipMode::None, ClipMode::Value, ClipMode::Norm}};
}

Profile reviewers_profile() {
  // What the paper's reviewers asked and the paper does not show, at the published budget:
  // the serial chain of 1-3 links on a cart (truly coupled, chaotic), 3 seeds, NORM clipping.
  std::vector<Setting> s;
  for (double links : {1, 2, 3}) s.push_back({chain, links, 3, 1000, 256});
  return {"reviewers",
          std::move(s),
          {Method::Regular, Method::Modified, Method::Combined, Method::Stopped},
          {ClipMode::Norm}};
}

inline int clip_rank(ClipMode c) { return static_cast<int>(c); }
inline int method_rank(Method m) { return static_cast<int>(m); }

struct Run {
  int task = 0;
  double complexity = 0;
  Method method = Method::Combined;
  ClipMode clip = ClipMode::Norm;
  long seed = first_seed;
  long epochs = 0;
  long samples = 0;
  bool use_float = false;  ///< the task program runs in float (as the reference's float32)

  [[nodiscard]] const TaskInfo& info() const { return tasks[task]; }
  [[nodiscard]] std::string name() const {
    return concat(info().name, "_", info().complexity_short, format_number(complexity), "_",
                  sbptt::label(method), "_", sbptt::to_string(clip), "_s", seed);
  }
  /// The task program's flags, without --csv (which depends on the out dir).
  [[nodiscard]] std::vector<std::string> flags() const {
    std::vector<std::string> f = split(info().model_flags, ' ');
    f.insert(f.end(), {info().complexity_flag, format_number(complexity), "--method",
                               std::string(sbptt::label(method)), "--clip",
                               sbptt::to_string(clip), "--epochs", std::to_string(epochs),
                               "--samples", std::to_string(samples), "--seed",
                               std::to_string(seed)});
    if (use_float) f.emplace_back("--float");
    return f;
  }
  /// The runs/<name>.run file: what the run is, so that summary.csv and the plots can be
  /// derived from the out dir alone, and a resumed sweep can check it plans the same run.
  [[nodiscard]] std::string description() const {
    std::string args;
    for (const auto& f : flags()) args += (args.empty() ? "" : " ") + f;
    return concat("task=", info().name, "\ncomplexity=", format_number(complexity),
                  "\nmethod=", sbptt::label(method), "\nclip=", sbptt::to_string(clip),
                  "\nseed=", seed, "\nepochs=", epochs, "\nsamples=", samples, "\nargs=", args,
                  "\n");
  }
  [[nodiscard]] double estimated_seconds() const {
    const double precision_cost = use_float ? 0.45 : 1.0;  // docs/benchmarks.md, float vs double
    return info().seconds_per_sample_epoch * method_cost(method) * precision_cost *
               static_cast<double>(epochs) * static_cast<double>(samples) +
           0.15;  // start-up and data generation
  }
  /// Grid order: task, complexity from easy to hard, method R M C S N, clip none value norm,
  /// seed.
  [[nodiscard]] auto order_key() const {
    const double difficulty = info().harder_when_smaller ? -complexity : complexity;
    return std::make_tuple(task, difficulty, method_rank(method), clip_rank(clip), seed);
  }
};

/// Whether `name` is the name of a run (`Run::name`: task_<complexity>_<method>_<clip>_s<seed>,
/// "cartpole_p4_C_norm_s42", its complexity a number): a file in runs/ under any other name is
/// a user's, and the runner neither counts nor removes it.
[[nodiscard]] inline bool is_run_name(std::string_view name) {
  const std::vector<std::string> parts = split(std::string(name), '_');
  if (parts.size() != 5) return false;
  const auto digits = [](std::string_view text) {
    return !text.empty() && text.find_first_not_of("0123456789") == std::string_view::npos;
  };
  const auto is_number = [](std::string_view text) {  // from_chars: whatever the locale
    double value = 0;
    const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
    return !text.empty() && error == std::errc() && end == text.data() + text.size() &&
           std::isfinite(value);
  };
  bool task_and_complexity = false;
  for (const TaskInfo& task : tasks) {
    const std::string_view prefix = task.complexity_short;
    task_and_complexity = task_and_complexity ||
                          (parts[0] == task.name && parts[1].starts_with(prefix) &&
                           is_number(std::string_view(parts[1]).substr(prefix.size())));
  }
  // The method and clip as a run's name writes them: the parsers' round trip, which also
  // refuses the long names ("combined") that parse_method accepts.
  const auto written_as_in_names = [&](const std::string& text, auto parse, auto write) {
    try {
      return std::string(write(parse(text))) == text;
    } catch (const sbptt::InvalidArgument&) {
      return false;
    }
  };
  return task_and_complexity &&
         written_as_in_names(parts[2], sbptt::parse_method,
                             [](Method m) { return sbptt::label(m); }) &&
         written_as_in_names(parts[3], sbptt::parse_clip_mode,
                             [](ClipMode c) { return sbptt::to_string(c); }) &&
         parts[4].starts_with('s') && digits(std::string_view(parts[4]).substr(1));
}

/// Reads a runs/<name>.run file back (for runs of earlier sweeps that this one did not plan).
inline std::optional<Run> parse_description(const std::string& text) {
  std::map<std::string, std::string> fields;
  for (const auto& line : split(text, '\n')) {
    const auto eq = line.find('=');
    if (eq != std::string::npos) fields[line.substr(0, eq)] = line.substr(eq + 1);
  }
  try {
    Run run;
    run.task = -1;
    for (int t = 0; t < task_count; ++t)
      if (fields["task"] == tasks[t].name) run.task = t;
    if (run.task < 0) return std::nullopt;
    run.complexity = parse_number("complexity", fields["complexity"], -1e300, 1e300);
    run.method = sbptt::parse_method(fields["method"]);
    run.clip = sbptt::parse_clip_mode(fields["clip"]);
    run.seed = parse_integer("seed", fields["seed"], 0, std::numeric_limits<long>::max());
    run.epochs = parse_integer("epochs", fields["epochs"], 0, 1'000'000'000);
    run.samples = parse_integer("samples", fields["samples"], 0, 1'000'000'000);
    run.use_float = fields["args"].ends_with(" --float");  // the one setting kept only in args
    if (run.description() != text) return std::nullopt;
    return run;
  } catch (const sbptt::Error&) {
    return std::nullopt;
  }
}

}  // namespace reproduce
