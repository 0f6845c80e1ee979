#pragma once
// The memory a task program may use, and the refusal of sizes whose run cannot fit in it.
//
// Linux lets a process allocate more than the machine has and kills it with SIGKILL when the
// pages are touched: no message, no exit code of the program's own. So the sizes are checked
// against the least of the machine's memory, the process's cgroup limit (Slurm's, a
// container's) and ulimit -v / -d before anything is generated. What is counted is a lower
// bound (the generated set, its two halves, the evaluation's records and one batch's
// trajectory; not the adjoints, gradients, threads' buffers or the program itself),
// so no size that fits is refused; a run that passes here and still runs out gets the
// out-of-memory message of `task_main`.
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <exception>
#include <fstream>
#include <optional>
#include <string>
#include <utility>

#include <sbptt/core/error.hpp>
#include <sbptt/core/types.hpp>
#include <sbptt/nn/network.hpp>

#include "task_options.hpp"

namespace sbptt::examples {

/// A number of bytes and what sets it ("physical memory", "ulimit -v", …).
struct MemoryBound {
  double bytes;
  std::string source;
};

namespace detail_memory {

/// The number in `path` (a cgroup's limit file), or none for "max", a missing file or a
/// value that means no limit (cgroup v1 writes 2⁶³ rounded down to a page).
inline std::optional<double> cgroup_limit(const std::string& path) {
  std::ifstream in(path);
  std::string text;
  if (!(in >> text) || text == "max") return std::nullopt;
  try {
    const double bytes = std::stod(text);
    if (bytes >= 1e18) return std::nullopt;
    return bytes;
  } catch (const std::exception&) {
    return std::nullopt;
  }
}

/// The least memory limit of this process's cgroup and the cgroups above it (Slurm limits the
/// job's cgroup and runs the task in one below it), v2 (`0::/path`) or v1 (`N:memory:/path`).
inline std::optional<double> own_cgroup_limit() {
  std::ifstream in("/proc/self/cgroup");
  std::optional<double> least;
  const auto up_from = [&](const std::string& root, std::string path, const char* file) {
    while (true) {
      const std::optional<double> limit = cgroup_limit(root + path + file);
      if (limit && (!least || *limit < *least)) least = limit;
      const auto slash = path.find_last_of('/');
      if (path.empty() || slash == std::string::npos) return;
      path.erase(slash);
    }
  };
  for (std::string line; std::getline(in, line);) {
    if (line.rfind("0::", 0) == 0) {
      up_from("/sys/fs/cgroup", line.substr(3), "/memory.max");
    } else if (const auto at = line.find(":memory:"); at != std::string::npos) {
      up_from("/sys/fs/cgroup/memory", line.substr(at + 8), "/memory.limit_in_bytes");
    }
  }
  return least;
}

}  // namespace detail_memory

/// The least of the bounds on what this process can hold.
inline MemoryBound usable_memory() {
  MemoryBound bound{static_cast<double>(sysconf(_SC_PHYS_PAGES)) *
                        static_cast<double>(sysconf(_SC_PAGE_SIZE)),
                    "physical memory"};
  const auto lower = [&](double bytes, const char* source) {
    if (bytes < bound.bytes) bound = {bytes, source};
  };
  if (const auto limit = detail_memory::own_cgroup_limit())
    lower(*limit, "the memory limit of its cgroup");
  for (const auto& [resource, source] : {std::pair{RLIMIT_AS, "ulimit -v"},
                                         std::pair{RLIMIT_DATA, "ulimit -d"}}) {
    rlimit limit{};
    if (getrlimit(resource, &limit) == 0 && limit.rlim_cur != RLIM_INFINITY)
      lower(static_cast<double>(limit.rlim_cur), source);
  }
  return bound;
}

/// Throws `InvalidArgument` naming the size flags when what a run holds cannot fit in
/// `usable_memory()`: the generated 2 × --samples states and the train and test halves copied
/// from them; the evaluation's buffers, which keep a record of the network's forward pass for
/// every sample of a set (a workspace sized for one sample, times --samples); and, when it
/// trains or dumps gradients, a batch's trajectory, whose every step holds its states and that
/// record. A train set from --init-states is only sized once read: its trajectory is left out.
template <class Scalar>
void require_memory_for_run(const TaskOptions& o, Index state_dim,
                            const Network<Scalar>& network) {
  typename Network<Scalar>::Workspace one_sample;
  network.size_forward(1, one_sample);
  const auto scalar_bytes = static_cast<double>(sizeof(Scalar));
  const auto samples = static_cast<double>(o.samples);
  const double record = static_cast<double>(one_sample.bytes()) / scalar_bytes;
  const double sets = 4.0 * samples * static_cast<double>(state_dim) + samples * record;
  const bool dump = !o.dump_gradients.empty();
  const double batch = !o.init_states.empty() || (o.epochs == 0 && !dump) ? 0.0
                       : dump ? samples
                              : static_cast<double>(std::min(o.batch, o.samples));
  const double trajectory = static_cast<double>(o.time.steps + 1) * batch *
                            (static_cast<double>(state_dim) + record);
  const double bytes = (sets + trajectory) * scalar_bytes;
  const MemoryBound usable = usable_memory();
  if (bytes <= usable.bytes) return;
  // As many decimals as it takes for the need to read larger than the bound ("0.8 GiB, more
  // than the 0.8 GiB" said nothing).
  int decimals = 1;
  const auto shown_with = [](double b, int places) {
    char text[32];
    std::snprintf(text, sizeof text, "%.*f GiB", places, b / (1024.0 * 1024.0 * 1024.0));
    return std::string(text);
  };
  while (decimals < 6 && shown_with(bytes, decimals) == shown_with(usable.bytes, decimals))
    ++decimals;
  const auto gib = [&](double b) { return shown_with(b, decimals); };
  const std::string batch_flag = dump ? "" : detail::concat(", --batch ", o.batch);
  throw InvalidArgument(detail::concat(
      "--samples ", o.samples, " (and as many test samples)", state_size_flags(o), batch_flag,
      " and --steps ",
      o.time.steps, " need at least ", gib(bytes), " (", sizeof(Scalar) == 4 ? "float" : "double",
      ", ", state_dim, " numbers a state: ", gib(sets * scalar_bytes),
      " for the sets and their evaluation, ", gib(trajectory * scalar_bytes),
      " for a batch's trajectory), more than the ", gib(usable.bytes), " this process may use (",
      usable.source, "); expected smaller sizes"));
}

}  // namespace sbptt::examples
