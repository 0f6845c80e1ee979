#pragma once
/// \file The descriptors a run's output files need at once, checked against `ulimit -n` before
/// any work (`run_training`, and the programs before they load anything).
///
/// A run keeps its log and its checkpoint's lock open from its start to its end. A write opens
/// one more at a time (the file, closed before its directory is opened to sync the rename), and
/// the first write of each file two: the directory and, one by one, the temporaries that killed
/// writers left, to remove them. That removal is best effort, so one spare number would let the
/// run go on and leave those copies behind without a word; the check asks for two. Under a limit
/// too low even for one, a run with a log and a checkpoint trained an epoch and then failed at
/// its checkpoint ("Too many open files"), and one with a log alone trained every epoch and
/// failed at the log's last sync.
#include <fcntl.h>
#include <sys/resource.h>

#include <algorithm>
#include <cerrno>
#include <cstddef>
#include <string>
#include <vector>

#include "sbptt/core/error.hpp"

namespace sbptt::detail {

/// The first `count` free descriptor numbers from 3 up: where the run's files will go, since it
/// opens each through `open_above_standard_streams` (a free 0, 1 or 2, a closed standard
/// stream, takes none of them).
inline std::vector<int> free_descriptors_above_standard_streams(int count) {
  std::vector<int> numbers;
  for (int fd = 3; static_cast<int>(numbers.size()) < count; ++fd)
    if (::fcntl(fd, F_GETFD) == -1 && errno == EBADF) numbers.push_back(fd);
  return numbers;
}

/// Throws IoError, led by `outputs` (the settings or flags that name the files, listed), when
/// the files a run keeps open (its log if `log`, its checkpoint's lock if `lock`) and the two a
/// write opens beside them cannot be open at once under the process's descriptor limit.
inline void require_descriptors_for_outputs(const std::vector<std::string>& outputs, bool log,
                                            bool lock) {
  if (outputs.empty()) return;
  const int held = int{log} + int{lock};
  const int needed = held + 2;
  rlimit limit{};
  if (::getrlimit(RLIMIT_NOFILE, &limit) != 0 || limit.rlim_cur == RLIM_INFINITY) return;
  const std::vector<int> free = free_descriptors_above_standard_streams(needed);
  // A limit bounds the numbers, not the count: one the parent left open past it takes a number
  // that raising the limit would free.
  const auto enough = static_cast<rlim_t>(free.back()) + 1;
  if (enough <= limit.rlim_cur) return;
  const auto free_now = std::count_if(free.begin(), free.end(), [&](int fd) {
    return static_cast<rlim_t>(fd) < limit.rlim_cur;
  });
  const bool beyond_hard = limit.rlim_max != RLIM_INFINITY && enough > limit.rlim_max;
  const char* held_names = log && lock ? "the log and the checkpoint's lock stay"
                           : log       ? "the log stays"
                                       : "the checkpoint's lock stays";
  std::string listed = outputs.front();
  for (std::size_t k = 1; k < outputs.size(); ++k)
    listed += (k + 1 == outputs.size() ? " and " : ", ") + outputs[k];
  throw IoError(concat(
      listed, ": ", needed, " files must be open at once beside the standard streams (",
      held == 0 ? std::string() : concat(held_names, " open while the run trains, and "),
      "a write opens up to two: the directory, and the file or a killed writer's temporary), "
      "but ulimit -n ", limit.rlim_cur, " leaves ", free_now,
      " free; expected ulimit -n ", enough, " or more",
      beyond_hard ? concat(" (past the hard limit ", limit.rlim_max,
                           ", which only an administrator can raise)")
                  : std::string()));
}

}  // namespace sbptt::detail
