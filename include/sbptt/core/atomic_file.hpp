#pragma once
/// \file Whole-file writes that never leave a half-written file, and that are durable.
///
/// A finished file appears at its path complete or not at all, and survives a machine crash
/// once the write returns:
/// 1. the content goes to an unnamed file (`O_TMPFILE`) in the target's directory, so a
///    process killed while writing leaves nothing behind (where the file system lacks
///    `O_TMPFILE`, to a named temporary `<name>.tmp.<pid>.<n>`, removed on every failure);
/// 2. the file is fsync'ed, given a temporary name and renamed over the target (rename is
///    atomic within one file system: a reader sees the old file or the new one);
/// 3. the directory is fsync'ed, so the rename itself is on disk.
///
/// A process killed between naming and renaming (or, without `O_TMPFILE`, while writing)
/// leaves its `<name>.tmp.<pid>.<n>`. Each process, at its first successful write of a file,
/// removes every such temporary whose writer is gone, so a rerun after a crash cleans up. Gone
/// means both: no process with that pid (as this process sees pids), and no lock on the file
/// (a writer holds `flock` on its temporary until the rename, which also covers a writer in
/// another pid namespace or on another NFS client).
///
/// A symbolic link is followed: the write replaces the link's final target, not the link.
/// An existing target keeps its permission bits (and its group and owner where the writer may
/// set them); a target the writer may not write (a write-protected file) is refused rather
/// than replaced, and so is a special file (a device, a FIFO). `check_output_path` makes the
/// same checks up front, before any work, and also refuses the file of the program's standard
/// output or error: replacing it would send what the program prints next to the old file.
#include <fcntl.h>
#include <signal.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <charconv>
#include <cerrno>
#include <climits>
#include <cstring>
#include <filesystem>
#include <mutex>
#include <string>
#include <string_view>
#include <unordered_set>

#include "sbptt/core/error.hpp"

namespace sbptt {

namespace detail {

/// Longest suffix a temporary name adds: ".tmp." + pid (≤ 10 digits) + "." + counter (≤ 20).
inline constexpr std::size_t temporary_suffix_bytes = 36;

[[nodiscard]] inline std::string os_reason(int error) { return std::strerror(error); }

/// `path` with every symbolic link of its last component followed (a dangling link gives the
/// path it points to). Throws `IoError` for a loop of links.
[[nodiscard]] inline std::filesystem::path final_target(const std::filesystem::path& path) {
  std::filesystem::path current = path;
  for (int hops = 0; hops < 40; ++hops) {
    std::error_code error;
    if (!std::filesystem::is_symlink(std::filesystem::symlink_status(current, error))) {
      return current;
    }
    const std::filesystem::path link = std::filesystem::read_symlink(current, error);
    if (error) return current;
    current = link.is_absolute() ? link : current.parent_path() / link;
  }
  throw IoError(concat("'", path.string(), "': too many levels of symbolic links (a loop?); "
                       "expected links that end at a file or a free name"));
}

/// `::open(path, flags, mode)`, the descriptor moved above 2 when it took the number of a
/// standard stream that was closed (a program started with `2>&-`): a file on fd 2 would
/// receive every message meant for stderr. −1 with errno set when either call fails.
[[nodiscard]] inline int open_above_standard_streams(const char* path, int flags,
                                                     ::mode_t mode = 0) {
  const int fd = ::open(path, flags, mode);
  if (fd < 0 || fd > 2) return fd;
  const int moved = ::fcntl(fd, F_DUPFD_CLOEXEC, 3);
  const int error = errno;
  ::close(fd);
  errno = error;
  return moved;
}

/// The directory a file at `target` lives in ("." for a bare name).
[[nodiscard]] inline std::filesystem::path directory_of(const std::filesystem::path& target) {
  return target.has_parent_path() ? target.parent_path() : std::filesystem::path(".");
}

/// Flushes a directory's entries (a rename in it) to disk. File systems that cannot sync a
/// directory (EINVAL) are not an error.
inline void sync_directory(const std::filesystem::path& directory, const std::string& for_path) {
  const int fd =
      open_above_standard_streams(directory.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) {
    throw IoError(concat("cannot open directory '", directory.string(), "' to sync '", for_path,
                         "': ", os_reason(errno)));
  }
  const int result = ::fsync(fd);
  const int error = errno;
  ::close(fd);
  if (result != 0 && error != EINVAL) {
    throw IoError(concat("cannot sync directory '", directory.string(), "' after writing '",
                         for_path, "': ", os_reason(error)));
  }
}

/// Writes all of `content` to `fd`, retrying short writes and EINTR; returns errno or 0.
[[nodiscard]] inline int write_all(int fd, std::string_view content) {
  while (!content.empty()) {
    const ::ssize_t written = ::write(fd, content.data(), content.size());
    if (written < 0) {
      if (errno == EINTR) continue;
      return errno;
    }
    content.remove_prefix(static_cast<std::size_t>(written));
  }
  return 0;
}

/// A number unique within this process for each temporary name.
[[nodiscard]] inline unsigned long long next_temporary_number() {
  static std::atomic<unsigned long long> counter{0};
  return counter.fetch_add(1, std::memory_order_relaxed);
}

/// The writer's pid if `entry` starts with `prefix` (`<target>.tmp.`) and goes on as
/// `<pid>.<n>`, else 0.
[[nodiscard]] inline long temporary_writer(std::string_view entry, std::string_view prefix) {
  const auto whole_number = [](std::string_view text, unsigned long long& value) {
    const char* last = text.data() + text.size();
    const auto [end, error] = std::from_chars(text.data(), last, value);
    return !text.empty() && error == std::errc() && end == last;
  };
  if (!entry.starts_with(prefix)) return 0;
  const std::string_view rest = entry.substr(prefix.size());
  const std::size_t dot = rest.find('.');
  unsigned long long pid = 0, counter = 0;
  if (dot == std::string_view::npos || !whole_number(rest.substr(0, dot), pid) ||
      !whole_number(rest.substr(dot + 1), counter) || pid > INT_MAX) {
    return 0;
  }
  return static_cast<long>(pid);
}

/// Whether the regular file at `path` can be locked now, that is no writer holds it.
[[nodiscard]] inline bool unlocked_regular_file(const std::filesystem::path& path) {
  const int fd =
      open_above_standard_streams(path.c_str(), O_RDONLY | O_NOFOLLOW | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) return false;
  struct stat status {};
  const bool unlocked = ::fstat(fd, &status) == 0 && S_ISREG(status.st_mode) &&
                        ::flock(fd, LOCK_EX | LOCK_NB) == 0;
  ::close(fd);
  return unlocked;
}

/// Removes the temporaries of `target` whose writers are gone (see the file comment). Once per
/// target and process: a scan at every write would add a directory read to every epoch's
/// checkpoint. Never throws: the write it follows has succeeded.
inline void remove_dead_writers_temporaries(const std::filesystem::path& target) noexcept {
  try {
    static std::mutex mutex;
    static std::unordered_set<std::string> swept;
    {
      const std::lock_guard<std::mutex> lock(mutex);
      if (!swept.insert(target.string()).second) return;
    }
    const std::string prefix = concat(target.filename().string(), ".tmp.");
    const long own = ::getpid();
    std::error_code error;
    for (std::filesystem::directory_iterator entry(directory_of(target), error), end;
         !error && entry != end; entry.increment(error)) {
      const long pid = temporary_writer(entry->path().filename().string(), prefix);
      const bool writer_gone = pid != 0 && pid != own &&
                               ::kill(static_cast<pid_t>(pid), 0) != 0 && errno == ESRCH;
      if (writer_gone && unlocked_regular_file(entry->path())) {
        std::error_code ignored;
        std::filesystem::remove(entry->path(), ignored);
      }
    }
  } catch (...) {  // a failed cleanup leaves a file behind, no more
  }
}

/// Whether `path` carries the append-only attribute (chattr +a), which even root's rename
/// cannot replace, nor, for a directory, rename any entry of. `statx` reads it without read
/// permission on the file; false where the system cannot tell.
[[nodiscard]] inline bool append_only(const std::filesystem::path& path) {
#if defined(STATX_ATTR_APPEND)
  struct statx attributes{};
  return ::statx(AT_FDCWD, path.c_str(), 0, STATX_BASIC_STATS, &attributes) == 0 &&
         (attributes.stx_attributes_mask & STATX_ATTR_APPEND) != 0 &&
         (attributes.stx_attributes & STATX_ATTR_APPEND) != 0;
#else
  (void)path;
  return false;
#endif
}

/// Why no file can be renamed to `target` in `directory` (chattr +a on either), or "".
[[nodiscard]] inline std::string append_only_reason(const std::filesystem::path& directory,
                                                    const std::filesystem::path& target) {
  if (append_only(directory))
    return concat("directory '", directory.string(), "' is append-only (chattr +a), so no file ",
                  "in it can be renamed into place; expected a directory without it");
  if (append_only(target))
    return "the file is append-only (chattr +a), so it cannot be replaced; expected a file "
           "without it (chattr -a)";
  return {};
}

}  // namespace detail

/// Fails before any work, with `IoError` naming `what` (e.g. "--csv") and the reason, when a
/// file could not later be written at `path` the way `write_file_atomically` writes it: empty
/// path; a directory or special file there; the file of this process's standard output or
/// error (what it printed after the rename would be lost); a missing or unwritable directory;
/// a write-protected existing file; an append-only file or directory; or a name too long for
/// the file system once the temporary suffix is added.
inline void check_output_path(const std::string& path, std::string_view what) {
  detail::require<IoError>(!path.empty(), what, ": the path is empty; expected a file path to "
                                                "write (an unset shell variable?)");
  const std::filesystem::path target =
      detail::prefixing_errors(std::string(what), [&] { return detail::final_target(path); });
  std::error_code error;
  const auto status = std::filesystem::status(target, error);
  // What is there, as the kernel resolves the path: the same file as `final_target` for a
  // chain of links, and also for /dev/stdout and /proc/self/fd/N, which name an open file (a
  // pipe there reads as a missing file to `final_target`).
  struct stat opened {};
  const bool opens = ::stat(path.c_str(), &opened) == 0;
  detail::require<IoError>(!opens || S_ISREG(opened.st_mode), what, " '", path,
                           "' exists and is not a regular file (",
                           S_ISDIR(opened.st_mode) ? "a directory" : "a special file",
                           "); expected a file path to write");
  auto is_stream = [&](int fd) {
    struct stat stream {};
    return opens && ::fstat(fd, &stream) == 0 && stream.st_dev == opened.st_dev &&
           stream.st_ino == opened.st_ino;
  };
  const bool output = is_stream(STDOUT_FILENO), error_stream = is_stream(STDERR_FILENO);
  detail::require<IoError>(!output && !error_stream, what, " '", path,
                           "' is this program's standard ",
                           output && error_stream ? "output and error"
                           : output               ? "output"
                                                  : "error",
                           "; expected a file of its own (a finished output replaces its file, "
                           "and what the program printed after that would be lost with the "
                           "old one)");
  const std::filesystem::path directory = detail::directory_of(target);
  detail::require<IoError>(std::filesystem::exists(directory, error), what, " '", path,
                           "': directory '", directory.string(), "' does not exist");
  detail::require<IoError>(std::filesystem::is_directory(directory, error), what, " '", path,
                           "': '", directory.string(), "' is not a directory");
  detail::require<IoError>(::access(directory.c_str(), W_OK) == 0, what, " '", path,
                           "': directory '", directory.string(), "' is not writable");
  detail::require<IoError>(!std::filesystem::exists(status) || ::access(target.c_str(), W_OK) == 0,
                           what, " '", path, "': the file exists and is write-protected; "
                           "expected a file this user may write (it is not replaced)");
  const std::string append_only = detail::append_only_reason(directory, target);
  detail::require<IoError>(append_only.empty(), what, " '", path, "': ", append_only);
  const long name_max = ::pathconf(directory.c_str(), _PC_NAME_MAX);
  const std::size_t limit = name_max > 0 ? static_cast<std::size_t>(name_max) : NAME_MAX;
  const std::size_t name = target.filename().string().size();
  detail::require<IoError>(name + detail::temporary_suffix_bytes <= limit, what, " '", path,
                           "': the file name is ", name, " bytes; with the temporary suffix "
                           "written beside it (up to ", detail::temporary_suffix_bytes,
                           " bytes) it would exceed this file system's limit of ", limit,
                           " bytes; expected a name of at most ",
                           limit - std::min(limit, detail::temporary_suffix_bytes), " bytes");
  detail::require<IoError>(target.string().size() + detail::temporary_suffix_bytes < PATH_MAX,
                           what, " '", path, "': the path is ", target.string().size(),
                           " bytes; expected fewer than ",
                           PATH_MAX - detail::temporary_suffix_bytes);
}

/// A file being written for an atomic, durable replacement of `path` (see the file comment).
/// Nothing is visible at the target until `commit()`; destroying it uncommitted discards it.
class AtomicFile {
public:
  /// Opens the temporary file. Throws `IoError` naming `path` and the OS reason.
  explicit AtomicFile(const std::string& path)
      : path_(path), target_(detail::final_target(path)),
        directory_(detail::directory_of(target_)) {
    detail::require<IoError>(!path.empty(), "cannot write a file at an empty path");
    // Before the temporary exists: in an append-only directory it could not be removed again.
    const std::string append_only = detail::append_only_reason(directory_, target_);
    detail::require<IoError>(append_only.empty(), "cannot write '", path_, "': ", append_only);
#ifdef O_TMPFILE
    fd_ = detail::open_above_standard_streams(directory_.c_str(), O_TMPFILE | O_WRONLY | O_CLOEXEC,
                                              0666);
    unnamed_ = fd_ >= 0 && ::access("/proc/self/fd", X_OK) == 0;
    if (fd_ >= 0 && !unnamed_) {
      ::close(fd_);
      fd_ = -1;
    }
#endif
    if (!unnamed_) {
      for (int attempt = 0; fd_ < 0 && attempt < 100; ++attempt) {
        temporary_ = temporary_name();
        fd_ = detail::open_above_standard_streams(temporary_.c_str(),
                                                  O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
        if (fd_ < 0 && errno != EEXIST) break;
      }
    }
    if (fd_ < 0) {
      temporary_.clear();
      throw IoError(detail::concat("cannot write '", path_, "' (in directory '",
                                   directory_.string(), "'): ", detail::os_reason(errno)));
    }
    // Held until the rename: no other process's cleanup takes a live temporary (a file system
    // without locks fails here and keeps its temporaries instead).
    [[maybe_unused]] const int locked = ::flock(fd_, LOCK_EX | LOCK_NB);
    keep_owner_and_mode();
  }
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;
  ~AtomicFile() { discard(); }

  /// Appends `text`. Throws `IoError` (e.g. disk full) naming the target and the reason.
  void write(std::string_view text) {
    const int error = detail::write_all(fd_, text);
    if (error != 0) fail("writing", error);
  }

  /// Syncs the file, renames it over the target and syncs the directory.
  void commit() {
    if (::fsync(fd_) != 0) fail("syncing", errno);
    if (unnamed_) {
      // An unnamed file gets a name only now, complete; a name already taken is skipped.
      const std::string self = "/proc/self/fd/" + std::to_string(fd_);
      int result = -1;
      for (int attempt = 0; result != 0 && attempt < 100; ++attempt) {
        temporary_ = temporary_name();
        result = ::linkat(AT_FDCWD, self.c_str(), AT_FDCWD, temporary_.c_str(), AT_SYMLINK_FOLLOW);
        if (result != 0 && errno != EEXIST) break;
      }
      if (result != 0) {
        temporary_.clear();
        fail("naming the temporary file for", errno);
      }
    }
    if (std::rename(temporary_.c_str(), target_.c_str()) != 0) {
      const int error = errno;
      const std::string temporary = temporary_;  // discard() forgets it
      discard();
      throw IoError(detail::concat("cannot rename '", temporary, "' to '", path_,
                                   "': ", detail::os_reason(error)));
    }
    ::close(fd_);  // only now: it holds the lock
    fd_ = -1;
    temporary_.clear();
    detail::remove_dead_writers_temporaries(target_);
    detail::sync_directory(directory_, path_);
  }

private:
  [[nodiscard]] std::string temporary_name() const {
    return detail::concat(target_.string(), ".tmp.", ::getpid(), ".",
                          detail::next_temporary_number());
  }

  void keep_owner_and_mode() {
    struct stat existing {};
    if (::stat(target_.c_str(), &existing) != 0) return;  // a new file: the umask decides
    // A rename would replace a device or a FIFO with a regular file (/dev/null for all users),
    // even for a caller that skipped `check_output_path`. Over a directory it fails by itself.
    if (!S_ISREG(existing.st_mode) && !S_ISDIR(existing.st_mode)) {
      discard();
      throw IoError(detail::concat("'", path_, "' exists and is a special file, not a regular "
                                   "file; it is not replaced"));
    }
    if (::access(target_.c_str(), W_OK) != 0) {
      const int error = errno;
      discard();
      throw IoError(detail::concat("'", path_, "' is not writable (", detail::os_reason(error),
                                   "); it is not replaced"));
    }
    // Owner and group as before where this user may set them (root; or a group it is in).
    if (::fchown(fd_, existing.st_uid, existing.st_gid) != 0) {
      [[maybe_unused]] const int ignored = ::fchown(fd_, static_cast<uid_t>(-1), existing.st_gid);
    }
    [[maybe_unused]] const int ignored = ::fchmod(fd_, existing.st_mode & 07777);
  }

  [[noreturn]] void fail(const char* doing, int error) {
    discard();
    throw IoError(detail::concat(doing, " '", path_, "' failed: ", detail::os_reason(error)));
  }

  void discard() noexcept {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
    if (!temporary_.empty()) ::unlink(temporary_.c_str());
    temporary_.clear();
  }

  std::string path_;
  std::filesystem::path target_, directory_;
  std::string temporary_;  ///< the name the data has before the rename; empty while unnamed
  int fd_ = -1;
  bool unnamed_ = false;
};

/// Writes `content` to `path` atomically and durably (see the file comment). Throws `IoError`
/// naming the path and the OS reason when it cannot.
inline void write_file_atomically(const std::string& path, std::string_view content) {
  AtomicFile file(path);
  file.write(content);
  file.commit();
}

}  // namespace sbptt
