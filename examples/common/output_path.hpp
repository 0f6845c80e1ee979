#pragma once
// The start-up check of an output file, shared by every program that writes one: a run that
// takes minutes or hours must not die at its first save, nor lose its work at the final rename.
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <string>
#include <system_error>

#include <sbptt/core/error.hpp>

namespace sbptt::examples {

/// Throws IoError naming `flag`, the user's `path` and the reason (the OS's where it has one)
/// unless `path` could be written: its directory exists and is writable, and the path itself is
/// a regular file or new. An empty path means "not asked for" and passes.
inline void require_writable(const std::string& path, const char* flag) {
  if (path.empty()) return;
  std::error_code error;
  const auto status = std::filesystem::status(path, error);
  detail::require<IoError>(!std::filesystem::exists(status) ||
                               std::filesystem::is_regular_file(status),
                           flag, " '", path, "' exists and is not a regular file (",
                           std::filesystem::is_directory(status) ? "a directory" : "a special file",
                           "); expected a file path to write");
  const std::filesystem::path parent = std::filesystem::absolute(path).parent_path();
  detail::require<IoError>(std::filesystem::exists(parent, error), flag, " '", path,
                           "': directory '", parent.string(), "' does not exist");
  detail::require<IoError>(std::filesystem::is_directory(parent, error), flag, " '", path,
                           "': '", parent.string(), "' is not a directory");
  if (::access(parent.c_str(), W_OK) != 0) {
    const int reason = errno;
    throw IoError(detail::concat(flag, " '", path, "': directory '", parent.string(),
                                 "' is not writable (", std::strerror(reason), ")"));
  }
}

}  // namespace sbptt::examples
