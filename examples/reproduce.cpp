// The reproduction runner (docs/reproduce.md): runs the paper's grid of task × complexity ×
// method × clip mode × seed as child processes of the task programs, in parallel, resumably,
// then writes <out>/summary.csv, prints a results table and draws the plots.
//
//   reproduce --profile quick                       # all three tasks, about 10 min on 2 cores
//   reproduce --profile paper --seeds 3 --jobs 8    # the published settings
//   reproduce --profile paper --tasks cartpole --complexities 4 --methods R,C --dry-run
//
// Resume contract: a child writes runs/<name>.partial.csv and its output goes to
// runs/<name>.partial.log; when it exits 0 (or 3: a non-finite value stopped training, a result
// in itself) the runner renames them to runs/<name>.log and runs/<name>.csv. On start every
// <name>.csv is kept and skipped, every .partial.* is discarded and its run redone. Children
// die with the runner (PR_SET_PDEATHSIG), even when it is SIGKILLed.
//
// Exit codes: 0 every planned run finished, 1 a run failed or an error, 2 bad flags,
// 130 interrupted (SIGINT/SIGTERM/SIGHUP; the finished runs are kept).
#include <fcntl.h>
#include <signal.h>
#include <sys/file.h>
#include <sys/ioctl.h>
#include <sys/prctl.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <sbptt/core/atomic_file.hpp>
#include <sbptt/core/error.hpp>
#include <sbptt/optim/clip.hpp>
#include <sbptt/train/arguments.hpp>
#include <sbptt/train/method.hpp>
#include <sbptt/train/training_log.hpp>

namespace fs = std::filesystem;
using sbptt::ClipMode;
using sbptt::InvalidArgument;
using sbptt::Method;
using sbptt::detail::concat;

namespace {

// ---------------------------------------------------------------------------------------------
// The tasks and the profiles. Retune the quick profile here.
// ---------------------------------------------------------------------------------------------

struct TaskInfo {
  const char* name;              ///< program name and summary label
  const char* complexity_flag;   ///< the task program's flag for the complexity axis
  const char* complexity_short;  ///< prefix in run names: p4, rc0.001, t4
  const char* complexity_title;  ///< what the complexity is (plots, table)
  bool harder_when_smaller;      ///< guidance: smaller rc is harder
  /// Rough cost of method R: seconds per (epoch · train sample), evaluation of the train and
  /// test sets included, one thread. Only used for the time estimate printed with the plan.
  double seconds_per_sample_epoch;
};

constexpr TaskInfo tasks[] = {
    // measured on the 2-core CI machine with --jobs 1 (runs/<name>.log ends with the wall time)
    {"cartpole", "--poles", "p", "poles", false, 1.4e-3},
    {"guidance", "--rc", "rc", "rc", true, 1.0e-3},
    {"quantum", "--target", "t", "target", false, 9.5e-3},
};
constexpr int task_count = static_cast<int>(std::size(tasks));

/// Relative cost of a method against R (C runs two reverse sweeps, S none through time).
double method_cost(Method m) {
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

constexpr int cartpole = 0, guidance = 1, quantum = 2;
constexpr long first_seed = 42;  // the reference's seed; more seeds count up from it

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
  // The published grids (paper.md §4–§6): 1000 epochs, 256 + 256 samples, one seed each.
  std::vector<Setting> s;
  for (double poles : {1, 2, 3, 4}) s.push_back({cartpole, poles, 1, 1000, 256});
  for (double rc : {1.0, 0.1, 0.01, 0.001}) s.push_back({guidance, rc, 1, 1000, 256});
  for (double target : {2, 3, 4}) s.push_back({quantum, target, 1, 1000, 256});
  return {"paper",
          std::move(s),
          {Method::Regular, Method::Modified, Method::Combined, Method::Stopped},
          {ClipMode::None, ClipMode::Value, ClipMode::Norm}};
}

// ---------------------------------------------------------------------------------------------
// Small helpers
// ---------------------------------------------------------------------------------------------

std::string format_number(double value) {
  char text[64];
  std::snprintf(text, sizeof text, "%g", value);
  return text;
}

std::string format_exact(double value) {
  char text[64];
  std::snprintf(text, sizeof text, "%.17g", value);
  return text;
}

std::string format_duration(double seconds) {
  const long s = std::lround(std::max(0.0, seconds));
  char text[64];
  if (s >= 3600) std::snprintf(text, sizeof text, "%ldh%02ldm", s / 3600, (s / 60) % 60);
  else if (s >= 60) std::snprintf(text, sizeof text, "%ldm%02lds", s / 60, s % 60);
  else std::snprintf(text, sizeof text, "%lds", s);
  return text;
}

std::vector<std::string> split(const std::string& text, char separator) {
  std::vector<std::string> parts;
  std::string part;
  std::istringstream in(text);
  while (std::getline(in, part, separator)) parts.push_back(part);
  if (!text.empty() && text.back() == separator) parts.emplace_back();
  return parts;
}

/// A comma-separated flag value: no empty items.
std::vector<std::string> parse_list(const std::string& flag, const std::string& text) {
  std::vector<std::string> items = split(text, ',');
  if (items.empty()) throw InvalidArgument(concat(flag, " needs a comma-separated list; got ''"));
  for (const auto& item : items)
    if (item.empty())
      throw InvalidArgument(concat(flag, " '", text, "' has an empty item; expected a list "
                                                     "like a,b,c"));
  return items;
}

bool same_number(double a, double b) {
  return std::abs(a - b) <= 1e-9 * std::max(std::abs(a), std::abs(b));
}

std::string read_text(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return {};
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

int clip_rank(ClipMode c) { return static_cast<int>(c); }
int method_rank(Method m) { return static_cast<int>(m); }

// ---------------------------------------------------------------------------------------------
// The plan
// ---------------------------------------------------------------------------------------------

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
    std::vector<std::string> f{info().complexity_flag, format_number(complexity), "--method",
                               std::string(sbptt::label(method)), "--clip",
                               sbptt::to_string(clip), "--epochs", std::to_string(epochs),
                               "--samples", std::to_string(samples), "--seed",
                               std::to_string(seed)};
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

/// Reads a runs/<name>.run file back (for runs of earlier sweeps that this one did not plan).
std::optional<Run> parse_description(const std::string& text) {
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
    run.complexity = sbptt::parse_number("complexity", fields["complexity"], -1e300, 1e300);
    run.method = sbptt::parse_method(fields["method"]);
    run.clip = sbptt::parse_clip_mode(fields["clip"]);
    run.seed = sbptt::parse_integer("seed", fields["seed"], 0, std::numeric_limits<long>::max());
    run.epochs = sbptt::parse_integer("epochs", fields["epochs"], 0, 1'000'000'000);
    run.samples = sbptt::parse_integer("samples", fields["samples"], 0, 1'000'000'000);
    run.use_float = fields["args"].ends_with(" --float");  // the one setting kept only in args
    if (run.description() != text) return std::nullopt;
    return run;
  } catch (const sbptt::Error&) {
    return std::nullopt;
  }
}

// ---------------------------------------------------------------------------------------------
// Command line
// ---------------------------------------------------------------------------------------------

constexpr const char* accepted_flags =
    "--profile quick|paper, --tasks cartpole,guidance,quantum, --methods R,M,C,S,N, "
    "--clips none,value,norm, --complexities LIST, --seeds N, --epochs N, --samples N, "
    "--float, --jobs N, --threads N, --out DIR, --bin-dir DIR, --dry-run, --no-plot, --python EXE, "
    "--plot-script FILE, --help";

struct Options {
  std::string profile = "quick";
  std::optional<std::vector<int>> tasks;
  std::optional<std::vector<Method>> methods;
  std::optional<std::vector<ClipMode>> clips;
  std::optional<std::vector<double>> complexities;
  std::optional<long> seeds, epochs, samples;
  long jobs = 2;
  long threads = 1;  ///< per task program; not part of a run's identity (see command_line)
  std::string out, bin_dir, python, plot_script;
  bool dry_run = false, plot = true, help = false, use_float = false;
};

std::string non_empty(const std::string& flag, std::string value) {
  if (value.empty()) throw InvalidArgument(concat(flag, " ''; expected a non-empty path"));
  return value;
}

Options parse_options(int argc, const char* const* argv) {
  Options o;
  sbptt::ArgumentCursor args(argc, argv);
  constexpr long many = 1'000'000'000;
  while (args.next()) {
    const std::string& f = args.flag();
    if (f == "--profile") {
      o.profile = args.value();
      if (o.profile != "quick" && o.profile != "paper")
        throw InvalidArgument(concat("--profile '", o.profile, "' is unknown; expected quick or "
                                                               "paper"));
    } else if (f == "--tasks") {
      std::vector<int> list;
      for (const auto& item : parse_list(f, args.value())) {
        int found = -1;
        for (int t = 0; t < task_count; ++t)
          if (item == tasks[t].name) found = t;
        if (found < 0)
          throw InvalidArgument(concat("--tasks: '", item, "' is not a task; expected "
                                                           "cartpole, guidance or quantum"));
        list.push_back(found);
      }
      o.tasks = list;
    } else if (f == "--methods") {
      std::vector<Method> list;
      for (const auto& item : parse_list(f, args.value())) {
        try {
          list.push_back(sbptt::parse_method(item));
        } catch (const InvalidArgument& e) {
          throw InvalidArgument(concat("--methods: ", e.what()));
        }
      }
      o.methods = list;
    } else if (f == "--clips") {
      std::vector<ClipMode> list;
      for (const auto& item : parse_list(f, args.value())) {
        try {
          list.push_back(sbptt::parse_clip_mode(item));
        } catch (const InvalidArgument& e) {
          throw InvalidArgument(concat("--clips: ", e.what()));
        }
      }
      o.clips = list;
    } else if (f == "--complexities") {
      std::vector<double> list;
      for (const auto& item : parse_list(f, args.value()))
        list.push_back(sbptt::parse_number(f, item, 0, 1e9));
      o.complexities = list;
    } else if (f == "--seeds") o.seeds = sbptt::parse_integer(f, args.value(), 1, 1000);
    else if (f == "--epochs") o.epochs = sbptt::parse_integer(f, args.value(), 1, many);
    else if (f == "--samples") o.samples = sbptt::parse_integer(f, args.value(), 1, many);
    else if (f == "--jobs") o.jobs = sbptt::parse_integer(f, args.value(), 1, 256);
    else if (f == "--threads") o.threads = sbptt::parse_integer(f, args.value(), 1, 256);
    else if (f == "--out") o.out = non_empty(f, args.value());
    else if (f == "--bin-dir") o.bin_dir = non_empty(f, args.value());
    else if (f == "--python") o.python = non_empty(f, args.value());
    else if (f == "--plot-script") o.plot_script = non_empty(f, args.value());
    else if (f == "--dry-run") args.no_value(), o.dry_run = true;
    else if (f == "--float") args.no_value(), o.use_float = true;
    else if (f == "--no-plot") args.no_value(), o.plot = false;
    else if (f == "--help") args.no_value(), o.help = true;
    else args.unknown(accepted_flags);
  }
  if (o.out.empty()) o.out = "out/" + o.profile;
  return o;
}

template <class T>
bool selected(const std::optional<std::vector<T>>& filter, const T& value) {
  return !filter || std::find(filter->begin(), filter->end(), value) != filter->end();
}

/// The runs of the profile after filters and overrides, in grid order.
std::vector<Run> make_plan(const Options& o) {
  const Profile profile = o.profile == "paper" ? paper_profile() : quick_profile();
  const auto methods = o.methods ? *o.methods : profile.methods;
  const auto clips = o.clips ? *o.clips : profile.clips;
  if (o.complexities) {
    for (double c : *o.complexities) {
      const bool known = std::any_of(profile.settings.begin(), profile.settings.end(),
                                     [&](const Setting& s) {
                                       return selected(o.tasks, s.task) &&
                                              same_number(s.complexity, c);
                                     });
      if (!known) {
        std::string available;
        for (const auto& s : profile.settings)
          if (selected(o.tasks, s.task))
            available += concat(available.empty() ? "" : ", ", tasks[s.task].name, " ",
                                format_number(s.complexity));
        throw InvalidArgument(concat("--complexities: ", format_number(c),
                                     " is no setting of profile ", profile.name,
                                     " for the selected tasks; available: ", available));
      }
    }
  }
  std::vector<Run> plan;
  for (const auto& s : profile.settings) {
    if (!selected(o.tasks, s.task)) continue;
    if (o.complexities &&
        std::none_of(o.complexities->begin(), o.complexities->end(),
                     [&](double c) { return same_number(c, s.complexity); }))
      continue;
    const long seeds = o.seeds.value_or(s.seeds);
    for (Method m : methods)
      for (ClipMode c : clips)
        for (long k = 0; k < seeds; ++k)
          plan.push_back({s.task, s.complexity, m, c, first_seed + k, o.epochs.value_or(s.epochs),
                          o.samples.value_or(s.samples), o.use_float});
  }
  // Drop duplicates (a method or clip listed twice) and sort into grid order.
  std::sort(plan.begin(), plan.end(),
            [](const Run& a, const Run& b) { return a.order_key() < b.order_key(); });
  plan.erase(std::unique(plan.begin(), plan.end(),
                         [](const Run& a, const Run& b) { return a.name() == b.name(); }),
             plan.end());
  return plan;
}

/// runs/<name><suffix>: the files of one run.
fs::path run_file(const fs::path& runs, const Run& run, const char* suffix) {
  return runs / (run.name() + suffix);
}

/// The task program's command line. --threads is passed here and kept out of Run::flags(),
/// which make the run's .run file: results are bitwise identical for any thread count
/// (docs/benchmarks.md), so a sweep resumed with another --threads keeps its finished runs.
std::vector<std::string> command_line(const Run& run, const fs::path& bin_dir,
                                      const fs::path& runs, long threads) {
  std::vector<std::string> argv{(bin_dir / run.info().name).string()};
  for (const auto& f : run.flags()) argv.push_back(f);
  argv.insert(argv.end(), {"--threads", std::to_string(threads), "--csv",
                           run_file(runs, run, ".partial.csv").string()});
  return argv;
}

// ---------------------------------------------------------------------------------------------
// Summaries of finished runs
// ---------------------------------------------------------------------------------------------

struct Summary {
  Run run;
  long epochs_done = 0;
  double final_test = NAN, min_test = NAN, final_train = NAN;
  double mean_seconds = NAN, total_seconds = 0;
  [[nodiscard]] std::string status() const {
    return epochs_done == run.epochs ? "ok" : "stopped";
  }
};

constexpr const char* summary_header =
    "task,complexity,method,clip,seed,epochs,final_test_loss,min_test_loss,final_train_loss,"
    "mean_seconds_per_epoch,total_seconds,status,run";

/// Reads a finished training log (DESIGN §4). Throws ParseError naming the file and line.
Summary summarize(const Run& run, const fs::path& csv) {
  const std::string text = read_text(csv);
  const auto lines = split(text, '\n');
  if (lines.empty() || lines[0] != sbptt::TrainingLog::header)
    throw sbptt::ParseError(concat("'", csv.string(), "': the first line is not the training-log "
                                                      "header '",
                                   sbptt::TrainingLog::header, "'"));
  Summary s{run};
  for (std::size_t i = 1; i < lines.size(); ++i) {
    if (lines[i].empty()) continue;
    const auto fields = split(lines[i], ',');
    const std::string where = concat("'", csv.string(), "', line ", i + 1);
    if (fields.size() != 8)
      throw sbptt::ParseError(concat(where, ": ", fields.size(), " fields, expected 8"));
    auto number = [&](std::size_t k) {
      char* end = nullptr;
      const double v = std::strtod(fields[k].c_str(), &end);
      if (fields[k].empty() || end != fields[k].c_str() + fields[k].size())
        throw sbptt::ParseError(concat(where, ", field ", k + 1, ": '", fields[k],
                                       "' is not a number"));
      return v;
    };
    const double train = number(2), test = number(3), seconds = number(7);
    s.final_train = train;
    s.final_test = test;
    s.min_test = s.epochs_done == 0 ? test : std::min(s.min_test, test);
    s.total_seconds += seconds;
    ++s.epochs_done;
  }
  if (s.epochs_done > 0) s.mean_seconds = s.total_seconds / static_cast<double>(s.epochs_done);
  return s;
}

std::string summary_csv(const std::vector<Summary>& rows) {
  std::string text = std::string(summary_header) + "\n";
  auto value = [](double v) { return std::isnan(v) ? std::string() : format_exact(v); };
  for (const auto& s : rows) {
    char seconds[96];
    if (s.epochs_done > 0)
      std::snprintf(seconds, sizeof seconds, "%.6f,%.6f", s.mean_seconds, s.total_seconds);
    else
      std::snprintf(seconds, sizeof seconds, ",%.6f", s.total_seconds);
    text += concat(s.run.info().name, ",", format_number(s.run.complexity), ",",
                   sbptt::label(s.run.method), ",", sbptt::to_string(s.run.clip), ",", s.run.seed,
                   ",", s.epochs_done, ",", value(s.final_test), ",", value(s.min_test), ",",
                   value(s.final_train), ",", seconds, ",", s.status(), ",", s.run.name(), "\n");
  }
  return text;
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

/// The results table: per task, complexity, method and clip mode, the final test loss over
/// seeds (median and min–max) and the mean training seconds per epoch.
void print_table(const std::vector<Summary>& rows) {
  std::printf("\n%-9s %-10s %-6s %-5s %5s  %-12s %-27s %9s  %s\n", "task", "complexity", "method",
              "clip", "seeds", "median test", "[min, max] over seeds", "s/epoch", "stopped");
  for (std::size_t i = 0; i < rows.size();) {
    std::size_t j = i;
    std::vector<double> finals;
    double seconds = 0;
    long seconds_count = 0, stopped = 0;
    const Run& r = rows[i].run;
    for (; j < rows.size() && rows[j].run.task == r.task &&
           same_number(rows[j].run.complexity, r.complexity) && rows[j].run.method == r.method &&
           rows[j].run.clip == r.clip;
         ++j) {
      if (!std::isnan(rows[j].final_test)) finals.push_back(rows[j].final_test);
      if (!std::isnan(rows[j].mean_seconds)) seconds += rows[j].mean_seconds, ++seconds_count;
      if (rows[j].status() != "ok") ++stopped;
    }
    char loss[32] = "-", spread[64] = "", time[32] = "-";
    if (!finals.empty()) {
      std::snprintf(loss, sizeof loss, "%.6g", median(finals));
      const auto [lo, hi] = std::minmax_element(finals.begin(), finals.end());
      if (finals.size() > 1) std::snprintf(spread, sizeof spread, "[%.6g, %.6g]", *lo, *hi);
    }
    if (seconds_count > 0)
      std::snprintf(time, sizeof time, "%.4f", seconds / static_cast<double>(seconds_count));
    std::printf("%-9s %-10s %-6s %-5s %5zu  %-12s %-27s %9s  %s\n", r.info().name,
                format_number(r.complexity).c_str(), std::string(sbptt::label(r.method)).c_str(),
                sbptt::to_string(r.clip).c_str(), j - i, loss, spread, time,
                stopped ? std::to_string(stopped).c_str() : "");
    i = j;
  }
}

// ---------------------------------------------------------------------------------------------
// Processes
// ---------------------------------------------------------------------------------------------

volatile std::sig_atomic_t interrupted = 0;
extern "C" void on_signal(int signal_number) { interrupted = signal_number; }

void install_signal_handlers() {
  struct sigaction action {};
  action.sa_handler = on_signal;
  sigemptyset(&action.sa_mask);
  for (int s : {SIGINT, SIGTERM, SIGHUP}) sigaction(s, &action, nullptr);
}

/// Forks and execs argv[0] with stdin from /dev/null and stdout + stderr into `log_fd` (or
/// inherited when -1). The child gets its own process group (a terminal's Ctrl-C reaches
/// only the runner, which then stops its children) and dies with the runner.
pid_t spawn(const std::vector<std::string>& argv, int log_fd, bool search_path = false) {
  std::vector<char*> pointers;
  for (const auto& a : argv) pointers.push_back(const_cast<char*>(a.c_str()));
  pointers.push_back(nullptr);
  const int null_fd = ::open("/dev/null", O_RDONLY | O_CLOEXEC);
  const pid_t parent = ::getpid();
  const pid_t pid = ::fork();
  if (pid == 0) {
    // Only async-signal-safe calls until exec.
    ::setpgid(0, 0);
    ::prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (::getppid() != parent) ::_exit(127);  // the runner died before prctl took effect
    struct sigaction action {};
    action.sa_handler = SIG_DFL;
    for (int s : {SIGINT, SIGTERM, SIGHUP}) ::sigaction(s, &action, nullptr);
    if (null_fd >= 0) ::dup2(null_fd, 0);
    if (log_fd >= 0) {
      ::dup2(log_fd, 1);
      ::dup2(log_fd, 2);
    }
    if (search_path) ::execvp(pointers[0], pointers.data());
    else ::execv(pointers[0], pointers.data());
    const char message[] = "reproduce: cannot execute the program\n";
    [[maybe_unused]] const auto ignored = ::write(2, message, sizeof message - 1);
    ::_exit(127);
  }
  if (null_fd >= 0) ::close(null_fd);
  return pid;
}

/// Runs a command to completion; returns its exit code (-1 when it did not exit normally).
int run_command(const std::vector<std::string>& argv, bool quiet) {
  int log_fd = -1;
  if (quiet) log_fd = ::open("/dev/null", O_WRONLY | O_CLOEXEC);
  const pid_t pid = spawn(argv, log_fd, true);
  if (log_fd >= 0) ::close(log_fd);
  if (pid < 0) return -1;
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0) {
    if (errno != EINTR) return -1;
    if (interrupted) ::kill(pid, SIGTERM);
  }
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

std::string describe_status(int status) {
  if (WIFEXITED(status)) return concat("exit code ", WEXITSTATUS(status));
  if (WIFSIGNALED(status)) return concat("killed by signal ", WTERMSIG(status));
  return "ended";
}

bool is_executable(const fs::path& path) {
  return ::access(path.c_str(), X_OK) == 0 && fs::is_regular_file(path);
}

fs::path own_directory(const char* argv0) {
  std::error_code error;
  const fs::path self = fs::read_symlink("/proc/self/exe", error);
  if (!error) return self.parent_path();
  return fs::absolute(argv0).parent_path();
}

std::string tail_of(const fs::path& log, std::size_t count) {
  const auto lines = split(read_text(log), '\n');
  std::string text;
  std::size_t shown = 0;
  for (auto it = lines.rbegin(); it != lines.rend() && shown < count; ++it) {
    if (it->empty()) continue;
    text = "    " + *it + "\n" + text;
    ++shown;
  }
  return text;
}

// ---------------------------------------------------------------------------------------------
// The sweep
// ---------------------------------------------------------------------------------------------

class Sweep {
public:
  Sweep(const Options& options, std::vector<Run> plan, fs::path bin_dir)
      : options_(options), plan_(std::move(plan)), bin_dir_(std::move(bin_dir)),
        out_(options.out), runs_(out_ / "runs") {}

  /// Returns the exit code of the runner.
  int execute() {
    fs::create_directories(runs_);
    lock();
    discard_partial_runs();
    std::vector<const Run*> todo;
    std::vector<std::string> mismatched;
    for (const Run& run : plan_) {
      const fs::path csv = runs_ / (run.name() + ".csv");
      if (!fs::exists(csv)) {
        todo.push_back(&run);
        continue;
      }
      if (read_text(runs_ / (run.name() + ".run")) != run.description())
        mismatched.push_back(run.name());
    }
    if (!mismatched.empty()) {
      std::cerr << "reproduce: " << mismatched.size() << " finished run(s) in " << runs_
                << " were made with other settings than planned now (e.g. " << mismatched[0]
                << ": see its .run file); rerun with the old settings, choose another --out, "
                   "or remove runs/<name>.* to redo them\n";
      return 1;
    }
    load_finished();
    double estimate = 0;
    for (const Run* run : todo) estimate += run->estimated_seconds();
    std::printf("reproduce: profile %s, %zu runs planned (%zu finished, %zu to do), --jobs %ld, "
                "--threads %ld, estimated %s of compute, about %s wall time\n",
                options_.profile.c_str(), plan_.size(), plan_.size() - todo.size(), todo.size(),
                options_.jobs, options_.threads, format_duration(estimate).c_str(),
                format_duration(estimate / static_cast<double>(std::min<std::size_t>(
                                               static_cast<std::size_t>(options_.jobs),
                                               std::max<std::size_t>(todo.size(), 1))))
                    .c_str());
    std::printf("reproduce: output in %s (runs/, summary.csv, plots/)\n", out_.c_str());
    std::fflush(stdout);
    // More threads than cores make the runs wait for each other; the spin-then-sleep pool
    // copes, but the seconds columns then measure contention, not the method.
    const unsigned cores = std::thread::hardware_concurrency();
    if (cores > 0 && options_.jobs * options_.threads > static_cast<long>(cores))
      std::cerr << "reproduce: note: --jobs " << options_.jobs << " x --threads "
                << options_.threads << " = " << options_.jobs * options_.threads
                << " threads on " << cores
                << " cores; the timing columns will include the contention\n";
    // Longest first: the best simple schedule for parallel jobs of unequal length.
    std::stable_sort(todo.begin(), todo.end(), [](const Run* a, const Run* b) {
      return a->estimated_seconds() > b->estimated_seconds();
    });
    write_summary();
    const int code = loop(todo);
    write_summary();
    if (code == 130) {
      finish_progress();
      std::cerr << "reproduce: interrupted; " << summaries_.size()
                << " runs are finished and kept; run the same command again to continue\n";
      return code;
    }
    finish_progress();
    std::vector<Summary> rows;
    for (const auto& [key, s] : summaries_) rows.push_back(s);
    print_table(rows);
    std::printf("\nsummary: %s\n", (out_ / "summary.csv").c_str());
    if (!failures_.empty()) {
      std::cerr << "reproduce: " << failures_.size() << " run(s) failed and will be redone by the "
                << "next sweep:\n";
      for (const auto& f : failures_) std::cerr << f;
    }
    return failures_.empty() ? 0 : 1;
  }

private:
  struct Child {
    const Run* run;
    pid_t pid;
    std::chrono::steady_clock::time_point started;
  };

  void lock() {
    const fs::path path = out_ / ".lock";
    lock_fd_ = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    if (lock_fd_ < 0) throw sbptt::IoError(concat("cannot open '", path.string(), "'"));
    if (::flock(lock_fd_, LOCK_EX | LOCK_NB) != 0)
      throw sbptt::IoError(concat("another reproduce is running in '", out_.string(),
                                  "' (it holds ", path.string(), ")"));
  }

  /// Partial training logs and outputs of runs a killed sweep left behind (or of failed runs),
  /// and temporaries of interrupted atomic writes: their runs are redone.
  void discard_partial_runs() {
    std::set<std::string> discarded;  // a run killed before its first epoch has no .partial.csv
    for (const auto& entry : fs::directory_iterator(runs_)) {
      const std::string file = entry.path().filename().string();
      const auto partial = file.find(".partial.");
      if (partial == std::string::npos && file.find(".tmp.") == std::string::npos) continue;
      if (partial != std::string::npos && (file.ends_with(".partial.csv") ||
                                           file.ends_with(".partial.log")))
        discarded.insert(file.substr(0, partial));
      fs::remove(entry.path());
    }
    for (const auto& entry : fs::directory_iterator(out_))
      if (entry.path().filename().string().rfind("summary.csv.tmp.", 0) == 0)
        fs::remove(entry.path());
    if (!discarded.empty())
      std::printf("reproduce: discarded %zu unfinished run(s) of an interrupted sweep; they are "
                  "redone\n",
                  discarded.size());
  }

  /// Every finished run in the out dir (also of earlier sweeps with other filters).
  void load_finished() {
    for (const auto& entry : fs::directory_iterator(runs_)) {
      const fs::path path = entry.path();
      if (path.extension() != ".run") continue;
      const fs::path csv = fs::path(path).replace_extension(".csv");
      if (!fs::exists(csv)) continue;
      const auto run = parse_description(read_text(path));
      if (!run || run->name() != path.stem().string()) {
        std::cerr << "reproduce: warning: ignoring " << path << " (not a run description)\n";
        continue;
      }
      add_summary(*run, csv);
    }
  }

  bool add_summary(const Run& run, const fs::path& csv) {
    try {
      summaries_[run.order_key()] = summarize(run, csv);
      return true;
    } catch (const sbptt::Error& e) {
      failures_.push_back(concat("  ", run.name(), ": ", e.what(), "\n"));
      return false;
    }
  }

  void write_summary() {
    std::vector<Summary> rows;
    for (const auto& [key, s] : summaries_) rows.push_back(s);
    sbptt::write_file_atomically((out_ / "summary.csv").string(), summary_csv(rows));
  }

  bool start(const Run& run) {
    const std::string name = run.name();
    fs::remove(run_file(runs_, run, ".partial.csv"));
    sbptt::write_file_atomically(run_file(runs_, run, ".run").string(), run.description());
    const auto argv = command_line(run, bin_dir_, runs_, options_.threads);
    // Like the CSV, the log gets its final name only when the run has finished.
    const fs::path log = run_file(runs_, run, ".partial.log");
    const int log_fd = ::open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    if (log_fd < 0) throw sbptt::IoError(concat("cannot write '", log.string(), "'"));
    std::string command = "#";
    for (const auto& a : argv) command += " " + a;
    command += "\n";
    [[maybe_unused]] const auto written = ::write(log_fd, command.data(), command.size());
    const pid_t pid = spawn(argv, log_fd);
    ::close(log_fd);
    if (pid < 0) {
      failures_.push_back(concat("  ", name, ": fork failed: ", std::strerror(errno), "\n"));
      return false;
    }
    running_.push_back({&run, pid, std::chrono::steady_clock::now()});
    return true;
  }

  /// A child ended: keep its log as a finished run, or record the failure.
  void finished(const Child& child, int status) {
    const Run& run = *child.run;
    const std::string name = run.name();
    const fs::path partial = run_file(runs_, run, ".partial.csv");
    const fs::path csv = run_file(runs_, run, ".csv");
    const fs::path partial_log = run_file(runs_, run, ".partial.log");
    {  // for retuning the profiles: the whole run, start-up and evaluation included
      const double wall =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - child.started).count();
      std::ofstream(partial_log, std::ios::app) << "# reproduce: " << describe_status(status)
                                                << " after " << wall << " s wall time\n";
    }
    std::string failure;
    if (WIFEXITED(status) && (WEXITSTATUS(status) == 0 || WEXITSTATUS(status) == 3)) {
      const bool logged = fs::exists(partial);
      if (logged || WEXITSTATUS(status) == 3) {
        // The log first: a crash between the two renames leaves a run to redo, never a
        // finished run whose log the next sweep would discard as partial.
        fs::rename(partial_log, run_file(runs_, run, ".log"));
        if (logged) {
          fs::rename(partial, csv);  // atomic: the run is finished exactly when this happens
        } else {
          // Stopped in the first epoch: no row was logged, which is the result.
          sbptt::write_file_atomically(csv.string(),
                                       std::string(sbptt::TrainingLog::header) + "\n");
        }
      } else {
        failure = concat("exited 0 but wrote no training log ", partial.string());
      }
      if (failure.empty()) {
        if (add_summary(run, csv)) {
          ++done_;
          write_summary();
        } else {
          fs::remove(csv);  // not a valid log: redo it next time
        }
        return;
      }
    } else if (WIFEXITED(status)) {
      const int code = WEXITSTATUS(status);
      failure = code == 2   ? "exit code 2 (bad flags)"
                : code == 127 ? "exit code 127 (could not execute the program)"
                              : concat("exit code ", code);
    } else if (WIFSIGNALED(status)) {
      if (interrupted) return;  // we stopped it
      failure = concat("killed by signal ", WTERMSIG(status), " (", strsignal(WTERMSIG(status)), ")");
    }
    failures_.push_back(concat("  ", name, ": ", failure, "; log ", partial_log.string(),
                               ":\n", tail_of(partial_log, 3)));
    if (!tty_) std::cerr << "reproduce: " << name << " failed: " << failure << "\n";
  }

  int loop(const std::vector<const Run*>& todo) {
    tty_ = ::isatty(2) != 0;
    total_ = plan_.size();
    done_ = plan_.size() - todo.size();
    started_ = std::chrono::steady_clock::now();
    std::size_t next = 0;
    auto last_progress = std::chrono::steady_clock::time_point{};
    while (true) {
      if (interrupted) {
        for (const auto& c : running_) ::kill(c.pid, SIGTERM);
        const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(3);
        while (!running_.empty()) {
          reap();
          if (std::chrono::steady_clock::now() > deadline)
            for (const auto& c : running_) ::kill(c.pid, SIGKILL);
          std::this_thread::sleep_for(std::chrono::milliseconds(20));
        }
        return 130;
      }
      bool changed = false;
      while (running_.size() < static_cast<std::size_t>(options_.jobs) && next < todo.size()) {
        start(*todo[next++]);
        changed = true;
      }
      if (running_.empty()) break;
      changed = reap() || changed;
      const auto now = std::chrono::steady_clock::now();
      if ((tty_ && now - last_progress > std::chrono::milliseconds(500)) || (!tty_ && changed)) {
        progress();
        last_progress = now;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    return 0;
  }

  /// Collects every ended child; true when one ended.
  bool reap() {
    bool any = false;
    for (auto it = running_.begin(); it != running_.end();) {
      int status = 0;
      const pid_t pid = ::waitpid(it->pid, &status, WNOHANG);
      if (pid == it->pid) {
        const Child child = *it;
        it = running_.erase(it);
        finished(child, status);
        any = true;
      } else {
        ++it;
      }
    }
    return any;
  }

  void progress() {
    const double elapsed =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - started_).count();
    std::string names;
    for (const auto& c : running_) names += (names.empty() ? "" : ", ") + c.run->name();
    std::string line = concat("[", done_, "/", total_, "] ",
                              names.empty() ? "done" : "running: " + names, "  ",
                              format_duration(elapsed));
    if (!failures_.empty()) line += concat("  (", failures_.size(), " failed)");
    if (tty_) {
      winsize size{};
      std::size_t width = 100;
      if (::ioctl(2, TIOCGWINSZ, &size) == 0 && size.ws_col > 10) width = size.ws_col;
      if (line.size() >= width) {  // shorten the names, keep the counts and the time
        const std::string time = "... " + format_duration(elapsed);
        line = line.substr(0, width - 1 - time.size()) + time;
      }
      std::fprintf(stderr, "\r%s\033[K", line.c_str());
      progress_shown_ = true;
    } else {
      std::fprintf(stderr, "%s\n", line.c_str());
    }
    std::fflush(stderr);
  }

  void finish_progress() {
    if (tty_ && progress_shown_) {
      progress();
      std::fprintf(stderr, "\n");
      progress_shown_ = false;
    }
  }

  const Options& options_;
  std::vector<Run> plan_;
  fs::path bin_dir_, out_, runs_;
  int lock_fd_ = -1;
  std::map<decltype(Run{}.order_key()), Summary> summaries_;
  std::vector<std::string> failures_;
  std::vector<Child> running_;
  std::size_t done_ = 0, total_ = 0;
  bool tty_ = false, progress_shown_ = false;
  std::chrono::steady_clock::time_point started_;
};

// ---------------------------------------------------------------------------------------------
// Plots
// ---------------------------------------------------------------------------------------------

void plot(const Options& o, const fs::path& own_dir) {
  std::vector<fs::path> scripts;
  if (!o.plot_script.empty()) scripts.push_back(o.plot_script);
  else
    scripts = {fs::path(__FILE__).parent_path().parent_path() / "tools" / "plot_results.py",
               own_dir.parent_path().parent_path() / "tools" / "plot_results.py",
               own_dir / "plot_results.py"};
  const auto script = std::find_if(scripts.begin(), scripts.end(),
                                   [](const fs::path& p) { return fs::is_regular_file(p); });
  if (script == scripts.end()) {
    std::cerr << "reproduce: warning: tools/plot_results.py not found (tried "
              << scripts.front() << "); no plots; pass --plot-script FILE\n";
    return;
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
  if (python.empty()) {
    std::cerr << "reproduce: warning: no python3 with matplotlib (apt-get install "
                 "python3-matplotlib); no plots\n";
    return;
  }
  std::fflush(stdout);
  const int code = run_command({python, script->string(), o.out}, false);
  if (code != 0)
    std::cerr << "reproduce: warning: " << script->string() << " failed (exit code " << code
              << "); no plots\n";
  else
    std::printf("plots: %s\n", (fs::path(o.out) / "plots").c_str());
}

void print_plan(const Options& o, const std::vector<Run>& plan, const fs::path& bin_dir) {
  double estimate = 0;
  std::size_t todo = 0;
  const fs::path runs = fs::path(o.out) / "runs";
  for (const auto& run : plan) {
    std::string command;
    for (const auto& a : command_line(run, bin_dir, runs, o.threads))
      command += (command.empty() ? "" : " ") + a;
    const bool finished = fs::exists(run_file(runs, run, ".csv"));
    std::printf("%-34s %s%s\n", run.name().c_str(), command.c_str(),
                finished ? "  (finished)" : "");
    if (!finished) estimate += run.estimated_seconds(), ++todo;
  }
  std::printf("%zu runs planned (profile %s, %zu finished, %zu to do), estimated %s of "
              "compute, about %s wall time with --jobs %ld\n",
              plan.size(), o.profile.c_str(), plan.size() - todo, todo,
              format_duration(estimate).c_str(),
              format_duration(estimate / static_cast<double>(std::min<std::size_t>(
                                             static_cast<std::size_t>(o.jobs),
                                             std::max<std::size_t>(todo, 1))))
                  .c_str(),
              o.jobs);
}

}  // namespace

int main(int argc, char** argv) {
  Options options;
  std::vector<Run> plan;
  try {
    options = parse_options(argc, argv);
    if (options.help) {
      std::printf("usage: reproduce [flags]\nflags: %s\nSee docs/reproduce.md.\n",
                  accepted_flags);
      return 0;
    }
    plan = make_plan(options);
    if (plan.empty())
      throw InvalidArgument(concat("the selection leaves no run of profile ", options.profile));
  } catch (const InvalidArgument& e) {
    std::cerr << "reproduce: " << e.what() << "\n";
    return 2;
  }
  const fs::path own_dir = own_directory(argv[0]);
  const fs::path bin_dir = options.bin_dir.empty() ? own_dir : fs::path(options.bin_dir);
  if (options.dry_run) {
    print_plan(options, plan, bin_dir);
    return 0;
  }
  try {
    for (const auto& run : plan) {
      const fs::path program = bin_dir / run.info().name;
      if (!is_executable(program))
        throw sbptt::IoError(concat("no executable task program '", program.string(),
                                    "'; build the examples or pass --bin-dir DIR"));
    }
    install_signal_handlers();
    Sweep sweep(options, plan, bin_dir);
    const int code = sweep.execute();
    if (code == 130) return code;
    if (options.plot) plot(options, own_dir);
    return code;
  } catch (const std::exception& e) {
    std::cerr << "reproduce: " << e.what() << "\n";
    return 1;
  }
}
