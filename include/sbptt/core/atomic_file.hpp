#pragma once
/// \file Whole-file writes that never leave a half-written file: the content goes to a
/// temporary file in the same directory, which is then renamed over the target (rename is
/// atomic within one file system, so a reader sees the old file or the new one).
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <functional>
#include <string>
#include <string_view>
#include <thread>
#include <unistd.h>

#include "sbptt/core/error.hpp"

namespace sbptt {

/// Writes `content` to `path` atomically. Throws `IoError` naming the path when the directory
/// cannot be written.
inline void write_file_atomically(const std::string& path, std::string_view content) {
  // Unique per process, thread and moment, so concurrent writers of one target cannot clobber
  // each other's temporaries; the last rename wins, and each renamed file is complete.
  const std::string temporary = detail::concat(
      path, ".tmp.", ::getpid(), ".", std::hash<std::thread::id>{}(std::this_thread::get_id()), ".",
      std::chrono::steady_clock::now().time_since_epoch().count());
  {
    std::ofstream out(temporary, std::ios::binary | std::ios::trunc);
    if (!out) throw IoError(detail::concat("cannot write '", temporary, "' (for '", path, "')"));
    out.write(content.data(), static_cast<std::streamsize>(content.size()));
    out.flush();
    if (!out) {
      std::remove(temporary.c_str());
      throw IoError(detail::concat("writing '", temporary, "' failed (disk full?)"));
    }
  }
  if (std::rename(temporary.c_str(), path.c_str()) != 0) {
    const int error = errno;  // before remove() can overwrite it
    std::remove(temporary.c_str());
    throw IoError(detail::concat("cannot rename '", temporary, "' to '", path,
                                 "': ", std::strerror(error)));
  }
}

}  // namespace sbptt
