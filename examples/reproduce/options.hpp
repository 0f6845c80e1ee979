// reproduce: the command line and the plan it selects from a profile.
#pragma once

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>
#include <string>
#include <string_view>
#include <vector>

#include <unistd.h>

#include <sbptt/optim/clip.hpp>
#include <sbptt/train/method.hpp>

#include "command_line.hpp"
#include "flag_values.hpp"
#include "limits.hpp"

#include "grid.hpp"

namespace reproduce {

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
  bool dry_run = false, plot = true, help = false, use_float = false;  // help: printed, exit 0
  // What to do with the plan (at most one; running it with --jobs when none is given):
  std::string emit;     ///< "parallel" or "slurm": print or write it for another executor
  bool merge = false;   ///< summary, table and figures from the finished runs; list the rest
  std::string run;      ///< run only the run of this name (what emitted commands do)
  long shard_index = 0, shard_count = 1;  ///< --shard K/N: the runs k with k % N == K - 1
};

/// Each item of a comma-separated flag value, parsed; a bad item's message names the flag.
template <class Parse>
auto parse_items(const std::string& flag, const std::string& text, Parse parse) {
  std::vector<decltype(parse(text))> list;
  for (const auto& item : parse_list(flag, text)) {
    try {
      list.push_back(parse(item));
    } catch (const InvalidArgument& e) {
      if (std::string_view(e.what()).starts_with(flag + " ")) throw;
      throw InvalidArgument(concat(flag, ": ", e.what()));
    }
  }
  return list;
}

inline int parse_task(const std::string& item) {
  for (int t = 0; t < task_count; ++t)
    if (item == tasks[t].name) return t;
  throw InvalidArgument(concat("'", item, "' is not a task; expected cartpole, guidance, "
                                          "quantum or chain"));
}

/// --shard K/N: the zero-based K and N.
inline std::pair<long, long> parse_shard(const std::string& text) {
  constexpr long count_limit = sbptt::examples::limits::max_count;
  const auto slash = text.find('/');
  if (slash == std::string::npos)
    throw InvalidArgument(concat("--shard '", text, "' is not K/N; expected e.g. 2/3"));
  const long count = parse_integer("--shard N", text.substr(slash + 1), 1, count_limit);
  return {parse_integer("--shard K", text.substr(0, slash), 1, count) - 1, count};
}

/// `text` if it is one of `choices`, else an error naming the flag and the choices.
inline std::string parse_choice(const std::string& flag, const std::string& text,
                                const std::vector<std::string>& choices) {
  if (std::find(choices.begin(), choices.end(), text) != choices.end()) return text;
  std::string expected;
  for (std::size_t k = 0; k < choices.size(); ++k)
    expected += concat(k == 0 ? "" : k + 1 == choices.size() ? " or " : ", ", choices[k]);
  throw InvalidArgument(concat(flag, " '", text, "' is unknown; expected ", expected));
}

/// The refusal of --out for `reason` ("--out 'DIR': <reason>").
inline InvalidArgument bad_out(const Options& o, const std::string& reason) {
  return InvalidArgument(concat("--out '", o.out, "': ", reason));
}

/// What --out may be, for the refusals that say so.
inline constexpr const char* expected_out = "expected a folder, or a path where one can be made";

/// Makes a folder in `existing`, the part of --out that exists, and removes it again: the
/// permission bits do not tell root, nor anyone, whether the file system takes a new folder
/// there (/proc, a full disk's inode table), and `--emit parallel`, which writes nothing
/// itself, would print commands that each fail at their first write. Whatever --out still
/// needs would be made in `existing`, on the same file system. Only the probe is made and
/// removed, never --out or a folder above it: several executors may be starting on the same
/// new --out at once (docs/reproduce.md).
inline void probe_output_folder(const Options& o, const fs::path& existing) {
  std::string probe = (existing / ".reproduce-probe-XXXXXX").string();
  if (::mkdtemp(probe.data()) == nullptr) {
    const int reason = errno;
    throw bad_out(o, concat("cannot make a folder in '", existing.string(), "' (",
                            std::strerror(reason), "); expected a folder this user may write "
                            "in, or a path where one can be made"));
  }
  std::error_code ignored;
  fs::remove(probe, ignored);
}

/// The parts of an existing --out that this invocation's work writes (the sweep, --merge, the
/// plots, the Slurm script) are, where they exist, of the kind it writes: otherwise the sweep
/// and --merge would fail at their first write with the file system's words, after the dry run
/// and --emit had said nothing.
inline void require_output_layout(const Options& o, const fs::path& out) {
  struct Part {
    const char* name;
    bool folder, written;
    const char* role;
  };
  for (const Part& part :
       {Part{"runs", true, true, "the folder where the runner keeps its runs"},
        Part{"summary.csv", false, true, "the runner's summary file"},
        Part{"plots", true, o.plot, "the folder of the plots, or --no-plot"},
        Part{"slurm", true, o.emit == "slurm", "the folder of --emit slurm's script and logs"}}) {
    if (!part.written) continue;
    auto refused = [&](const char* kind) {
      return bad_out(o, concat("'", part.name, "' in it is ", kind, "; expected ", part.role,
                               " (move it away, then run again)"));
    };
    std::error_code error;
    const fs::path path = out / part.name;
    const fs::file_status status = fs::status(path, error);
    if (!fs::exists(status)) {
      // A link to nothing: the first write would fail where it leads, in the system's words.
      if (fs::is_symlink(fs::symlink_status(path, error)))
        throw refused("a symbolic link to nothing");
      continue;
    }
    const bool folder = fs::is_directory(status), file = fs::is_regular_file(status);
    if (part.folder ? folder : file) continue;
    throw refused(folder ? "a folder" : file ? "a file" : "a special file");
  }
}

/// --out is a folder, or a path where one can be made, that this user may write in (a dry
/// run only reads it): otherwise every mode would fail at its first write, with the file
/// system's words and without the flag.
inline void require_output_folder(const Options& o) {
  std::error_code error;
  const fs::path out = fs::absolute(o.out, error);
  // Linux refuses a name part over NAME_MAX (255 bytes) and a path over PATH_MAX (4096) at the
  // first write, in words that name neither the flag nor the part; the files under --out add
  // at most 128 bytes (runs/<name>.partial.csv.tmp.<suffix>).
  for (const fs::path& part : out)
    if (part.native().size() > 255)
      throw bad_out(o, concat("a name of ", part.native().size(),
                              " bytes in it; expected at most 255 (NAME_MAX)"));
  if (out.native().size() > 4096 - 128)
    throw bad_out(o, concat(out.native().size(), " bytes; expected a path of at most ",
                            4096 - 128, " (PATH_MAX less room for the files in it)"));
  fs::path existing = out;
  while (!fs::exists(existing, error) && existing.has_relative_path()) {
    // A link to nothing exists for mkdir (EEXIST) but not for exists().
    if (fs::is_symlink(fs::symlink_status(existing, error)))
      throw bad_out(o, concat("'", existing.string(), "' is a symbolic link to nothing; ",
                              expected_out));
    existing = existing.parent_path();
  }
  if (!fs::is_directory(existing, error)) {
    const std::string what = fs::is_regular_file(existing, error) ? "is a file" : "is not a folder";
    const bool itself = existing == out;
    throw InvalidArgument(concat("--out '", o.out, "'",
                                 itself ? "" : concat(": '", existing.string(), "'"), " ", what,
                                 "; ", expected_out));
  }
  if (existing == out) require_output_layout(o, out);
  if (o.dry_run) return;
  if (::access(existing.c_str(), W_OK | X_OK) != 0) {
    const int reason = errno;
    throw bad_out(o, concat("this user may not write in '", existing.string(), "' (",
                            std::strerror(reason), "); expected a folder it may write in"));
  }
  probe_output_folder(o, existing);
}

inline Options parse_options(int argc, const char* const* argv) {
  // The task programs' limit: a value they would refuse is refused here, before any run starts.
  constexpr long count_limit = sbptt::examples::limits::max_count;
  Options o;
  sbptt::examples::CommandLine cli(
      "reproduce",
      "Runs the paper's grid (task x complexity x method x clip x seed) with the task programs, "
      "resumably, here (--jobs), through GNU parallel or Slurm (--emit), or in shards; writes "
      "summary.csv, a results table and figures. See docs/reproduce.md.");
  cli.value("--profile", "NAME", "the grid and budget: quick (about 10 min), paper (the "
            "published settings) or reviewers (the cart chain at the published budget)",
            o.profile, [&](const std::string& v) {
              o.profile = parse_choice("--profile", v, {"quick", "paper", "reviewers"});
            });
  cli.value("--tasks", "LIST", "tasks to run, comma-separated: cartpole, guidance, quantum, chain",
            "all", [&](const std::string& v) { o.tasks = parse_items("--tasks", v, parse_task); });
  cli.value("--methods", "LIST", "gradient methods, comma-separated: R, M, C, S, N",
            "the profile's", [&](const std::string& v) {
              o.methods = parse_items("--methods", v, [](const std::string& item) {
                return sbptt::parse_method(item);
              });
            });
  cli.value("--clips", "LIST", "clip modes, comma-separated: none, value, norm",
            "the profile's", [&](const std::string& v) {
              o.clips = parse_items("--clips", v, [](const std::string& item) {
                return sbptt::parse_clip_mode(item);
              });
            });
  cli.value("--complexities", "LIST", "settings to keep, comma-separated (poles, rc or target); "
            "each a number in [0, 1e9] that the profile has", "all",
            [&](const std::string& v) {
              o.complexities = parse_items("--complexities", v, [](const std::string& item) {
                return parse_number("--complexities", item, 0, 1e9);
              });
            });
  cli.value("--seeds", "N", "seeds per setting (42, 43, ...); an integer in [1, 1000]",
            "the profile's", [&](const std::string& v) {
              o.seeds = parse_integer("--seeds", v, 1, 1000);
            });
  const std::string count_range = concat("an integer in [1, ", count_limit, "]");
  cli.value("--epochs", "N", "epochs of every run; " + count_range, "the profile's",
            [&](const std::string& v) { o.epochs = parse_integer("--epochs", v, 1, count_limit); });
  cli.value("--samples", "N", "training samples of every run; " + count_range, "the profile's",
            [&](const std::string& v) {
              o.samples = parse_integer("--samples", v, 1, count_limit);
            });
  cli.flag("--float", "train in float (the paper's precision); default double",
           [&] { o.use_float = true; });
  cli.integer("--jobs", o.jobs, 1, 256, "runs at once");
  cli.integer("--threads", o.threads, 1, 256, "threads of each task program (no part of a "
              "run's identity)");
  cli.path("--out", o.out, "output folder", "out/<profile>")->type_name("DIR");
  cli.path("--bin-dir", o.bin_dir, "folder of the task programs", "beside reproduce")
      ->type_name("DIR");
  cli.flag("--dry-run", "print the plan and the measured time estimate; run nothing",
           [&] { o.dry_run = true; });
  cli.value("--emit", "parallel|slurm", "print one command per unfinished run for GNU parallel, "
            "or write a Slurm array script", "none", [&](const std::string& v) {
              o.emit = parse_choice("--emit", v, {"parallel", "slurm"});
            });
  cli.value("--shard", "K/N", "run only every N-th run from the K-th (1 <= K <= N)", "1/1",
            [&](const std::string& v) {
              std::tie(o.shard_index, o.shard_count) = parse_shard(v);
            });
  cli.value("--run", "NAME", "run only the run of this name (what emitted commands do)", "none",
            [&](const std::string& name) {
              if (name.empty())
                throw InvalidArgument("--run '' is an empty name; expected the name of a run "
                                      "of the plan (--dry-run lists them)");
              o.run = name;
            });
  cli.flag("--merge", "summary, table and figures from the finished runs; list the missing",
           [&] { o.merge = true; });
  cli.flag("--no-plot", "skip the figures", [&] { o.plot = false; });
  cli.path("--python", o.python, "Python interpreter for the figures", "python3")
      ->type_name("EXE");
  cli.path("--plot-script", o.plot_script, "plotting script", "tools/plot_results.py");
  if (!cli.parse(argc, argv)) {
    o.help = true;
    return o;
  }
  if (o.out.empty()) o.out = "out/" + o.profile;
  const std::vector<std::pair<bool, const char*>> modes{
      {o.dry_run, "--dry-run"}, {!o.emit.empty(), "--emit"}, {o.merge, "--merge"},
      {!o.run.empty(), "--run"}};
  std::string chosen;
  for (const auto& [on, flag] : modes)
    if (on) chosen += concat(chosen.empty() ? "" : " and ", flag);
  if (chosen.find(" and ") != std::string::npos)
    throw InvalidArgument(concat(chosen, " exclude each other; expected at most one"));
  if (!o.run.empty() && o.shard_count > 1)
    throw InvalidArgument("--run and --shard exclude each other; --run names one run");
  if (!o.run.empty()) o.plot = false;  // one run of many: --merge draws the figures
  require_output_folder(o);
  return o;
}

template <class T>
inline bool selected(const std::optional<std::vector<T>>& filter, const T& value) {
  return !filter || std::find(filter->begin(), filter->end(), value) != filter->end();
}

/// The runs of the profile after filters and overrides, in grid order.
inline std::vector<Run> make_plan(const Options& o) {
  const Profile profile = o.profile == "paper"       ? paper_profile()
                          : o.profile == "reviewers" ? reviewers_profile()
                                                     : quick_profile();
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

/// The share of the plan this process takes: one shard (--shard K/N: every N-th run from the
/// K-th, in grid order, so the shards are disjoint and cover the plan) or one run (--run).
inline std::vector<Run> select_share(const Options& o, const std::vector<Run>& plan) {
  std::vector<Run> share;
  for (std::size_t k = 0; k < plan.size(); ++k)
    if (static_cast<long>(k % static_cast<std::size_t>(o.shard_count)) == o.shard_index &&
        (o.run.empty() || plan[k].name() == o.run))
      share.push_back(plan[k]);
  if (!o.run.empty() && share.empty())
    throw InvalidArgument(concat("--run '", o.run, "' is no run of the plan; --dry-run lists "
                                                   "them"));
  return share;
}

}  // namespace reproduce
