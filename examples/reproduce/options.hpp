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

#include <sbptt/train/task_options.hpp>

#include "grid.hpp"

namespace reproduce {

inline constexpr const char* accepted_flags =
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

inline std::string non_empty(const std::string& flag, std::string value) {
  if (value.empty()) throw InvalidArgument(concat(flag, " ''; expected a non-empty path"));
  return value;
}

inline Options parse_options(int argc, const char* const* argv) {
  // The task programs' limit: a value they would refuse is refused here, before any run starts.
  constexpr long count_limit = sbptt::max_count;
  Options o;
  sbptt::ArgumentCursor args(argc, argv);
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
    else if (f == "--epochs") o.epochs = sbptt::parse_integer(f, args.value(), 1, count_limit);
    else if (f == "--samples") o.samples = sbptt::parse_integer(f, args.value(), 1, count_limit);
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

}  // namespace reproduce
