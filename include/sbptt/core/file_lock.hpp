#pragma once
/// \file An exclusive `flock` on a lock file, held while the object lives.
///
/// The lock file is created when missing and never removed: removing it while another process
/// has it open, waiting or about to lock, would let two holders in. flock locks end with their
/// process, so a SIGKILLed holder leaves none held, and two opens of one file conflict within
/// one process as between two.
#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <utility>

#include "sbptt/core/atomic_file.hpp"
#include "sbptt/core/error.hpp"

namespace sbptt::detail {

class FileLock {
public:
  FileLock() = default;
  FileLock(const FileLock&) = delete;
  FileLock& operator=(const FileLock&) = delete;
  FileLock(FileLock&& other) noexcept
      : fd_(std::exchange(other.fd_, -1)), error_(std::exchange(other.error_, 0)) {}
  FileLock& operator=(FileLock&& other) noexcept {
    std::swap(fd_, other.fd_);
    std::swap(error_, other.error_);
    return *this;
  }
  ~FileLock() {
    if (fd_ >= 0) ::close(fd_);  // closing releases the lock
  }

  /// Takes the lock on `path`; with `wait` false returns an unheld lock when another holds
  /// it (`busy()`) or the file system cannot lock. Throws `IoError` when `path` cannot be
  /// opened.
  static FileLock take(const std::filesystem::path& path, bool wait) {
    FileLock lock;
    lock.fd_ = open_above_standard_streams(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    if (lock.fd_ < 0)
      throw IoError(concat("cannot open the lock file '", path.string(), "': ",
                           std::strerror(errno)));
    while (::flock(lock.fd_, LOCK_EX | (wait ? 0 : LOCK_NB)) != 0) {
      if (errno == EINTR && wait) continue;
      lock.error_ = errno;
      ::close(std::exchange(lock.fd_, -1));
      break;
    }
    return lock;
  }

  [[nodiscard]] bool held() const { return fd_ >= 0; }
  /// Whether another open of the file holds the lock (as opposed to a file system without
  /// locks, or no attempt).
  [[nodiscard]] bool busy() const { return error_ == EWOULDBLOCK; }
  /// errno of the failed flock (0 when held or not tried): ENOLCK, EOPNOTSUPP and the like
  /// say that the file system takes no locks.
  [[nodiscard]] int error() const { return error_; }

private:
  int fd_ = -1;
  int error_ = 0;  ///< errno of a failed flock
};

}  // namespace sbptt::detail
