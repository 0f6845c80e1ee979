#pragma once
// The descriptors a run's output files need at once, checked against `ulimit -n` before any
// work.
//
// A run keeps its log (--csv) and its checkpoint's lock (--checkpoint) open from its start to
// its end, and each write opens one more descriptor at a time (the file being written, then its
// directory to sync the rename). Under a limit too low for that, a run trained every epoch and
// then failed at its first save ("Too many open files"), the trained parameters lost.
#include <fcntl.h>
#include <sys/resource.h>
#include <unistd.h>

#include <cerrno>
#include <string>
#include <vector>

#include <sbptt/core/error.hpp>

namespace sbptt::examples {

/// How many of `wanted` more descriptors this process can open now, found by opening them: the
/// limit alone does not tell, because descriptors a parent left open count against it too.
/// `wanted` when opening fails for another reason than the limit (not this check's to judge).
inline int openable_descriptors(int wanted) {
  std::vector<int> opened;
  int failure = 0;
  while (static_cast<int>(opened.size()) < wanted) {
    const int fd = ::open("/", O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (fd < 0) {
      failure = errno;
      break;
    }
    opened.push_back(fd);
  }
  for (const int fd : opened) ::close(fd);
  if (failure != 0 && failure != EMFILE) return wanted;
  return static_cast<int>(opened.size());
}

/// Throws IoError, naming `flags`, when the `held` files a run keeps open and the one a write
/// opens beside them cannot be open at once under the process's descriptor limit.
/// `held_names` says what the held files are ("the log and the checkpoint's lock").
inline void require_descriptors_for_outputs(const std::string& flags, int held,
                                            const std::string& held_names) {
  const int needed = held + 1;
  const int available = openable_descriptors(needed);
  if (available >= needed) return;
  rlimit limit{};
  ::getrlimit(RLIMIT_NOFILE, &limit);
  const auto soft = static_cast<unsigned long long>(limit.rlim_cur);
  throw IoError(detail::concat(
      flags, ": ", needed, needed == 1 ? " file" : " files", " must be open at once (",
      held == 0 ? std::string() : held_names + (held == 1 ? " stays" : " stay") +
                                      " open while the run trains, and ",
      "each write opens one more), but ulimit -n ", soft, " leaves ", available,
      " to open; expected ulimit -n ", soft + static_cast<unsigned long long>(needed - available),
      " or more"));
}

}  // namespace sbptt::examples
