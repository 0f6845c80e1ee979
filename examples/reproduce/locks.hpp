// reproduce: the locks that let several executors (a --jobs pool, shards, GNU parallel, Slurm
// array tasks) share one output folder. runs/<name>.lock is held (flock, exclusive) by the
// one process that runs or cleans up that run; <out>/.lock is held briefly by whoever rewrites
// summary.csv. flock locks die with their process, so a SIGKILLed executor leaves none held.
#pragma once

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <string>
#include <utility>

#include <sbptt/core/atomic_file.hpp>
#include <sbptt/core/error.hpp>

#include "text.hpp"

namespace reproduce {

/// An flock on a lock file (created when missing, never removed: removing a lock file while
/// another process waits on it would let two holders in).
class FileLock {
public:
  FileLock() = default;
  FileLock(const FileLock&) = delete;
  FileLock& operator=(const FileLock&) = delete;
  FileLock(FileLock&& other) noexcept : fd_(std::exchange(other.fd_, -1)) {}
  FileLock& operator=(FileLock&& other) noexcept {
    std::swap(fd_, other.fd_);
    return *this;
  }
  ~FileLock() {
    if (fd_ >= 0) ::close(fd_);  // closing releases the lock
  }

  /// Takes the lock on `path`; with `wait` false returns an unheld lock when another process
  /// holds it.
  static FileLock take(const fs::path& path, bool wait) {
    FileLock lock;
    lock.fd_ = sbptt::detail::open_above_standard_streams(path.c_str(),
                                                          O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    if (lock.fd_ < 0)
      throw sbptt::IoError(concat("cannot open the lock file '", path.string(), "': ",
                                  std::strerror(errno)));
    while (::flock(lock.fd_, LOCK_EX | (wait ? 0 : LOCK_NB)) != 0) {
      if (errno == EINTR && wait) continue;
      ::close(std::exchange(lock.fd_, -1));
      break;
    }
    return lock;
  }

  [[nodiscard]] bool held() const { return fd_ >= 0; }

private:
  int fd_ = -1;
};

/// runs/<name>.lock: held while a process runs the run or removes its partial files.
inline FileLock try_lock_run(const fs::path& runs, const std::string& name) {
  return FileLock::take(runs / (name + ".lock"), false);
}

/// Whether another process holds the run's lock now (it is running the run).
inline bool run_is_locked(const fs::path& runs, const std::string& name) {
  if (!fs::exists(runs / (name + ".lock"))) return false;
  return !try_lock_run(runs, name).held();
}

/// <out>/.lock: held while summary.csv is rebuilt, so that concurrent executors write it one
/// after the other, each from the files on disk.
inline FileLock lock_summary(const fs::path& out) { return FileLock::take(out / ".lock", true); }

}  // namespace reproduce
