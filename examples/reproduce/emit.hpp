// reproduce: the plan handed to other executors. Each unfinished run becomes one command,
// `reproduce <the same selection> --run NAME`, which runs that run under its lock and finishes
// its files exactly as the local executor does; so GNU parallel (--emit parallel), a Slurm job
// array (--emit slurm) or any scheduler running the lines fill the same output folder, and
// `reproduce <the same selection> --merge` collects it.
#pragma once

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <sbptt/core/atomic_file.hpp>
#include <sbptt/core/number_text.hpp>

#include "finished_run.hpp"
#include "options.hpp"

namespace reproduce {

using sbptt::label;
using sbptt::to_string;

/// `word` quoted for a POSIX shell (unchanged when it needs no quotes).
inline std::string shell_quote(const std::string& word) {
  const bool plain = !word.empty() && std::all_of(word.begin(), word.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) != 0 ||
           std::string_view("-_./=,:+@%").find(c) != std::string_view::npos;
  });
  if (plain) return word;
  std::string quoted = "'";
  for (char c : word) quoted += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return quoted + "'";
}

inline std::string shell_line(const std::vector<std::string>& words) {
  std::string line;
  for (const auto& w : words) {
    if (!line.empty()) line += ' ';
    line += shell_quote(w);
  }
  return line;
}

/// `word` as one argument of an #SBATCH line. sbatch splits those lines at blanks outside
/// quotes and reads a backslash inside double quotes as an escape (Slurm 22.05): a folder with
/// a blank or a quote in its name stays one argument.
inline std::string sbatch_quote(const std::string& word) {
  std::string quoted = "\"";
  for (char c : word) {
    if (c == '"' || c == '\\') quoted += '\\';
    quoted += c;
  }
  return quoted + "\"";
}

/// `path` absolute and normal, as the emitted commands and scripts name it: the same from any
/// directory.
inline std::string absolute_path(const fs::path& path) {
  return fs::absolute(path).lexically_normal().string();
}

inline bool is_control_character(char c) {
  return std::iscntrl(static_cast<unsigned char>(c)) != 0;
}

/// Refuses, before any work, an --out that the Slurm scripts cannot name: sbatch reads '%' in
/// --output as a pattern (%a, %j, %x, ...), and a backslash there as an escape of the patterns
/// (Slurm's documentation), which the logs' %a needs; a line break would end the line.
inline void require_slurm_folder(const Options& o) {
  const std::string dir = absolute_path(o.out);
  const auto bad = std::find_if(dir.begin(), dir.end(), [](char c) {
    return c == '%' || c == '\\' || is_control_character(c);
  });
  if (bad != dir.end())
    throw InvalidArgument(concat("--out '", sbptt::detail::printable(o.out, 200),
                                 "' with --emit slurm: its path holds ",
                                 *bad == '%' ? "'%', which sbatch reads as a file-name pattern"
                                 : *bad == '\\' ? "a backslash, which sbatch reads as an escape "
                                                  "of the logs' file-name pattern"
                                                : "a control character",
                                 "; expected a folder without them"));
}

/// Refuses, before any work, a path that --emit parallel cannot put on one line (the reader
/// takes a command a line): a control character in --out, --bin-dir or the runner's own path,
/// as the commands name them (absolute: the working directory's name counts too).
inline void require_one_line_paths(const Options& o, const fs::path& self,
                                   const fs::path& bin_dir) {
  for (const auto& [what, path] : {std::pair{"--out", fs::path(o.out)},
                                   std::pair{"--bin-dir", bin_dir},
                                   std::pair{"the runner's own path", self}}) {
    const std::string text = absolute_path(path);
    if (std::any_of(text.begin(), text.end(), is_control_character))
      throw InvalidArgument(concat(what, " '", sbptt::detail::printable(text, 200),
                                   "' with --emit parallel: its path holds a control character, "
                                   "and the commands go one a line; expected a folder without "
                                   "one"));
  }
}

/// The flags that select the plan, with absolute folders: the same plan from any directory.
inline std::vector<std::string> selection_flags(const Options& o, const fs::path& bin_dir) {
  auto joined = [](const auto& items, auto text) {
    std::string list;
    for (const auto& item : items) {
      if (!list.empty()) list += ',';
      list += text(item);
    }
    return list;
  };
  std::vector<std::string> f{"--profile", o.profile};
  if (o.tasks)
    f.insert(f.end(), {"--tasks", joined(*o.tasks, [](int t) { return tasks[t].name; })});
  if (o.methods)
    f.insert(f.end(), {"--methods", joined(*o.methods, [](Method m) { return label(m); })});
  if (o.clips)
    f.insert(f.end(), {"--clips", joined(*o.clips, [](ClipMode c) { return to_string(c); })});
  if (o.complexities)
    f.insert(f.end(), {"--complexities", joined(*o.complexities, format_exact)});
  if (o.seeds) f.insert(f.end(), {"--seeds", std::to_string(*o.seeds)});
  if (o.epochs) f.insert(f.end(), {"--epochs", std::to_string(*o.epochs)});
  if (o.samples) f.insert(f.end(), {"--samples", std::to_string(*o.samples)});
  if (o.use_float) f.emplace_back("--float");
  f.insert(f.end(), {"--threads", std::to_string(o.threads), "--out", absolute_path(o.out),
                     "--bin-dir", absolute_path(bin_dir)});
  return f;
}

/// The runs of `plan` that are not finished in the output folder, in plan order.
inline std::vector<Run> unfinished(const Options& o, const std::vector<Run>& plan,
                                   FinishedRuns& finished) {
  finished = scan_finished(fs::path(o.out) / "runs");
  std::vector<Run> left;
  for (const auto& run : plan)
    if (!is_finished(finished, run)) left.push_back(run);
  return left;
}

/// --emit parallel: one command per unfinished run on stdout, for `| parallel --jobs N`.
inline int emit_parallel(const Options& o, const std::vector<Run>& plan, const fs::path& self,
                         const fs::path& bin_dir) {
  FinishedRuns finished;
  std::vector<std::string> command{self.string()};
  const auto selection = selection_flags(o, bin_dir);
  command.insert(command.end(), selection.begin(), selection.end());
  const std::vector<Run> left = unfinished(o, plan, finished);
  for (const auto& run : left) {
    auto line = command;
    line.insert(line.end(), {"--run", run.name()});
    std::printf("%s\n", shell_line(line).c_str());
  }
  // On stderr, so that the pipe to parallel takes the commands alone.
  if (left.empty())
    std::fprintf(stderr, "reproduce: all %zu planned runs are finished; nothing to hand out\n",
                 plan.size());
  else
    std::fprintf(stderr, "reproduce: %zu of %zu planned runs to do, a command each on standard "
                 "output\n", left.size(), plan.size());
  return 0;
}

/// --emit slurm: <out>/slurm/{runs.txt, array.sh, merge.sh}, and the sbatch commands. Array
/// task i runs the i-th name that array.sh holds (runs.txt lists the same names for the
/// reader): sbatch keeps a copy of the script it was given, so an array still queued runs its
/// own list when a later --emit rewrites the files. The logs carry the job's number, so a
/// later wave does not overwrite them. --jobs K tasks at once. The time limit is the longest
/// run's expected wall time (measured on finished runs when there are any) twice over, plus 5
/// minutes for start-up and a slow node; the CPUs are --threads.
inline int emit_slurm(const Options& o, const std::vector<Run>& plan, const fs::path& self,
                      const fs::path& bin_dir) {
  FinishedRuns finished;
  const std::vector<Run> left = unfinished(o, plan, finished);
  if (left.empty()) {
    std::printf("reproduce: all %zu planned runs are finished; nothing to submit\n", plan.size());
    return 0;
  }
  const fs::path dir = absolute_path(fs::path(o.out) / "slurm");
  fs::create_directories(dir / "logs");
  std::string names, quoted_names;
  double longest = 0;
  for (const auto& run : left) {
    names += run.name() + "\n";
    quoted_names += "  " + shell_quote(run.name()) + "\n";
    longest = std::max(longest, finished.expected_seconds(run));
  }
  sbptt::write_file_atomically((dir / "runs.txt").string(), names);
  const long minutes = std::lround(std::ceil((2 * longest + 300) / 60));
  std::vector<std::string> command{self.string()};
  const auto selection = selection_flags(o, bin_dir);
  command.insert(command.end(), selection.begin(), selection.end());
  const std::string job = concat("sbptt-", o.profile);
  const std::string array = concat(
      "#!/bin/bash\n# One array task per unfinished run of the plan when it was written (as in ",
      dir.string(), "/runs.txt),\n# by reproduce --emit slurm. Resubmitting it is harmless: a "
      "finished run is skipped.\n#SBATCH --job-name=", job, "\n#SBATCH --array=0-",
      left.size() - 1, "%", o.jobs, "\n#SBATCH --ntasks=1\n#SBATCH --cpus-per-task=", o.threads,
      "\n#SBATCH --time=", minutes, "\n#SBATCH --output=",
      sbatch_quote((dir / "logs" / "run_%A_%a.log").string()),
      "\nset -euo pipefail\nruns=(\n", quoted_names, ")\nrun=${runs[$SLURM_ARRAY_TASK_ID]}\n",
      "exec ", shell_line(command), " --run \"$run\"\n");
  // The figures' own flags too: on a cluster --python names a venv's python, as the system's
  // often lacks matplotlib, and the merge job would then draw nothing, with a warning alone.
  std::vector<std::string> merging = command;
  if (!o.plot) merging.emplace_back("--no-plot");
  if (o.plot && !o.python.empty())
    merging.insert(merging.end(),
                   {"--python", o.python.find('/') == std::string::npos
                                    ? o.python  // a name on PATH
                                    : absolute_path(o.python)});
  if (o.plot && !o.plot_script.empty())
    merging.insert(merging.end(),
                   {"--plot-script", absolute_path(o.plot_script)});
  merging.emplace_back("--merge");
  const std::string merge = concat(
      "#!/bin/bash\n# Collects the array's runs into summary.csv, the table and the figures.\n"
      "#SBATCH --job-name=", job, "-merge\n#SBATCH --ntasks=1\n#SBATCH --cpus-per-task=1\n"
      "#SBATCH --time=30\n#SBATCH --output=",
      sbatch_quote((dir / "logs" / "merge_%j.log").string()), "\nexec ", shell_line(merging),
      "\n");
  sbptt::write_file_atomically((dir / "array.sh").string(), array);
  sbptt::write_file_atomically((dir / "merge.sh").string(), merge);
  std::printf("reproduce: %zu of %zu planned runs to do; wrote %s/array.sh (--array=0-%zu%%%ld, "
              "%ld CPU(s) and %ld min per task) and %s/merge.sh. Submit with:\n",
              left.size(), plan.size(), dir.c_str(), left.size() - 1, o.jobs, o.threads,
              minutes, dir.c_str());
  std::printf("job=$(sbatch --parsable %s) && sbatch --dependency=afterany:${job%%%%;*} %s\n",
              shell_quote((dir / "array.sh").string()).c_str(),
              shell_quote((dir / "merge.sh").string()).c_str());
  return 0;
}

}  // namespace reproduce
