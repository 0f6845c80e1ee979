#pragma once
/// \file Whole-file writes that never leave a half-written file: the content goes to a
/// temporary file in the same directory, which is then renamed over the target (rename is
/// atomic within one file system, so a reader sees the old file or the new one).
#include <cstdio>
#include <fstream>
#include <string>
#include <string_view>
#include <unistd.h>

#include "sbptt/core/error.hpp"

namespace sbptt {

/// Writes `content` to `path` atomically. Throws `IoError` naming the path when the directory
/// cannot be written.
inline void write_file_atomically(const std::string& path, std::string_view content) {
  const std::string temporary = path + ".tmp." + std::to_string(::getpid());
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
    std::remove(temporary.c_str());
    throw IoError(detail::concat("cannot rename '", temporary, "' to '", path, "'"));
  }
}

}  // namespace sbptt
