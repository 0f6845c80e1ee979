// reproduce: files that count as finished only once they are on disk. rename() alone is atomic
// but not durable: after a machine crash the new name can point at a file whose blocks were
// never written (an empty or cut training log). So the content is fsync'ed before the rename,
// and the directory after it.
#pragma once

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <string>
#include <string_view>

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

/// Writes `content` to `path` through a temporary in the same directory (`<path>.tmp.<pid>`),
/// durably: a reader or a crash sees the old file or the whole new one.
inline void write_durably(const fs::path& path, std::string_view content) {
  const fs::path temporary = concat(path.string(), ".tmp.", ::getpid());
  const int fd = ::open(temporary.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0)
    throw sbptt::IoError(concat("cannot write '", temporary.string(), "' (for '", path.string(),
                                "'): ", std::strerror(errno)));
  std::size_t done = 0;
  int error = 0;
  while (done < content.size() && error == 0) {
    const auto written = ::write(fd, content.data() + done, content.size() - done);
    if (written < 0 && errno != EINTR) error = errno;
    if (written > 0) done += static_cast<std::size_t>(written);
  }
  if (::close(fd) != 0 && error == 0) error = errno;
  if (error != 0) {
    fs::remove(temporary);
    throw sbptt::IoError(concat("writing '", temporary.string(), "' (for '", path.string(),
                                "') failed: ", std::strerror(error)));
  }
  try {
    rename_durably(temporary, path);  // fsyncs the temporary, renames, fsyncs the folder
  } catch (const sbptt::IoError&) {
    fs::remove(temporary);
    throw;
  }
}

}  // namespace reproduce
