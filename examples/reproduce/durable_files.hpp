// reproduce: files that count as finished only once they are on disk. rename() alone is atomic
// but not durable: after a machine crash the new name can point at a file whose blocks were
// never written (an empty or cut training log). So the content is fsync'ed before the rename,
// and the directory after it. Whole files the runner writes go through the library's
// sbptt::write_file_atomically, which syncs the same way; what stays here renames a file that
// is already written (a run's partial log and CSV to their final names), which it does not do.
#pragma once

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <string>

#include <sbptt/core/error.hpp>

#include "text.hpp"

namespace reproduce {

/// fsync()s a file or a directory; throws IoError naming it and the reason.
inline void sync_to_disk(const fs::path& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0)
    throw sbptt::IoError(concat("cannot open '", path.string(), "' to sync it: ",
                                std::strerror(errno)));
  const int synced = ::fsync(fd);
  const int error = errno;
  ::close(fd);
  if (synced != 0)
    throw sbptt::IoError(concat("cannot sync '", path.string(), "': ", std::strerror(error)));
}

/// Renames `from` to `to` so that `to` is on disk, whole, once this returns.
inline void rename_durably(const fs::path& from, const fs::path& to) {
  sync_to_disk(from);
  std::error_code error;
  fs::rename(from, to, error);
  if (error)
    throw sbptt::IoError(concat("cannot rename '", from.string(), "' to '", to.string(),
                                "': ", error.message()));
  sync_to_disk(to.parent_path().empty() ? fs::path(".") : to.parent_path());
}

}  // namespace reproduce
