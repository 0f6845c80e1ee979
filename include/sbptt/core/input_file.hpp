#pragma once
/// \file A file opened for reading, or an `IoError` with the system's reason it cannot be.
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>

#include "sbptt/core/error.hpp"

namespace sbptt::detail {

/// `path` opened for reading (binary). Throws `IoError` "<who>'<path>' is a directory;
/// expected <kind>" or "<who>cannot open '<path>' for reading (<the system's reason>)". A
/// directory is named first because on Linux it opens without error and fails only when read.
[[nodiscard]] inline std::ifstream open_for_reading(const std::filesystem::path& path,
                                                    const std::string& who,
                                                    const std::string& kind) {
  std::error_code error;
  require<IoError>(!std::filesystem::is_directory(path, error), who, "'", path.string(),
                   "' is a directory; expected ", kind);
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    const int reason = errno;
    throw IoError(concat(who, "cannot open '", path.string(), "' for reading (",
                         std::strerror(reason), ")"));
  }
  return in;
}

}  // namespace sbptt::detail
