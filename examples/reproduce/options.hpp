// reproduce: the command line and the plan it selects from a profile.
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

#include <sbptt/optim/clip.hpp>
#include <sbptt/train/method.hpp>

#include "argument_cursor.hpp"
#include "flag_values.hpp"
#include "limits.hpp"

#include "grid.hpp"

namespace reproduce {

inline constexpr const char* accepted_flags =
    "--profile quick|paper, --tasks cartpole,guidance,quantum, --methods R,M,C,S,N, "
    "--clips none,value,norm, --complexities LIST, --seeds N, --epochs N, --samples N, "
    "--float, --jobs N, --threads N, --out DIR, --bin-dir DIR, --dry-run, --emit parallel|slurm, "
    "--shard K/N, --run NAME, --merge, --no-plot, --python EXE, --plot-script FILE, --help";

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
  // What to do with the plan (at most one; running it with --jobs when none is given):
  std::string emit;     ///< "parallel" or "slurm": print or write it for another executor
  bool merge = false;   ///< summary, table and figures from the finished runs; list the rest
  std::string run;      ///< run only the run of this name (what emitted commands do)
  long shard_index = 0, shard_count = 1;  ///< --shard K/N: the runs k with k % N == K - 1
};

inline std::string non_empty(const std::string& flag, std::string value) {
  if (value.empty()) throw InvalidArgument(concat(flag, " ''; expected a non-empty path"));
  return value;
}

/// Each item of a comma-separated flag value, parsed; a bad item's message names the flag.
template <class Parse>
auto parse_items(const std::string& flag, const std::string& text, Parse parse) {
  std::vector<decltype(parse(text))> list;
  for (const auto& item : parse_list(flag, text)) {
    try {
      list.push_back(parse(item));
    } catch (const InvalidArgument& e) {
      throw InvalidArgument(concat(flag, ": ", e.what()));
    }
  }
  return list;
}

inline Options parse_options(int argc, const char* const* argv) {
  // The task programs' limit: a value they would refuse is refused here, before any run starts.
  constexpr long count_limit = sbptt::examples::limits::max_count;
  Options o;
  sbptt::examples::ArgumentCursor args(argc, argv);
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
      o.methods = parse_items(f, args.value(), [](const std::string& item) {
        return sbptt::parse_method(item);
      });
    } else if (f == "--clips") {
      o.clips = parse_items(f, args.value(), [](const std::string& item) {
        return sbptt::parse_clip_mode(item);
      });
    } else if (f == "--complexities") {
      std::vector<double> list;
      for (const auto& item : parse_list(f, args.value()))
        list.push_back(parse_number(f, item, 0, 1e9));
      o.complexities = list;
    } else if (f == "--seeds") o.seeds = parse_integer(f, args.value(), 1, 1000);
    else if (f == "--epochs") o.epochs = parse_integer(f, args.value(), 1, count_limit);
    else if (f == "--samples") o.samples = parse_integer(f, args.value(), 1, count_limit);
    else if (f == "--jobs") o.jobs = parse_integer(f, args.value(), 1, 256);
    else if (f == "--threads") o.threads = parse_integer(f, args.value(), 1, 256);
    else if (f == "--out") o.out = non_empty(f, args.value());
    else if (f == "--bin-dir") o.bin_dir = non_empty(f, args.value());
    else if (f == "--python") o.python = non_empty(f, args.value());
    else if (f == "--plot-script") o.plot_script = non_empty(f, args.value());
    else if (f == "--dry-run") args.no_value(), o.dry_run = true;
    else if (f == "--merge") args.no_value(), o.merge = true;
    else if (f == "--run") o.run = non_empty(f, args.value());
    else if (f == "--emit") {
      o.emit = args.value();
      if (o.emit != "parallel" && o.emit != "slurm")
        throw InvalidArgument(concat("--emit '", o.emit, "' is unknown; expected parallel or "
                                                         "slurm"));
    } else if (f == "--shard") {
      const std::string text = args.value();
      const auto slash = text.find('/');
      if (slash == std::string::npos)
        throw InvalidArgument(concat("--shard '", text, "' is not K/N; expected e.g. 2/3"));
      o.shard_count =
          parse_integer("--shard N", text.substr(slash + 1), 1, count_limit);
      o.shard_index =
          parse_integer("--shard K", text.substr(0, slash), 1, o.shard_count) -
          1;
    }
    else if (f == "--float") args.no_value(), o.use_float = true;
    else if (f == "--no-plot") args.no_value(), o.plot = false;
    else if (f == "--help") args.no_value(), o.help = true;
    else args.unknown(accepted_flags);
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
  return o;
}

template <class T>
inline bool selected(const std::optional<std::vector<T>>& filter, const T& value) {
  return !filter || std::find(filter->begin(), filter->end(), value) != filter->end();
}

/// The runs of the profile after filters and overrides, in grid order.
inline std::vector<Run> make_plan(const Options& o) {
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
