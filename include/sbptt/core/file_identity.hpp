#pragma once
/// \file Whether two paths name the same file, by file-system identity rather than by string:
/// `a.txt`, `./a.txt`, a symbolic link to it and a hard link to it are one file. A path that
/// does not exist yet is identified by its directory's identity and its name, so two spellings
/// of one new output are caught too.
#include <sys/stat.h>

#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "sbptt/core/atomic_file.hpp"
#include "sbptt/core/error.hpp"

namespace sbptt {

/// One file a program reads or writes, named as the user named it ("--csv").
struct FileRole {
  std::string what;
  std::string path;
  bool output = true;
};

namespace detail {

/// (device, inode) of the file, or of its directory plus its name when it does not exist.
struct FileKey {
  std::uint64_t device = 0, inode = 0;
  std::string name;  ///< empty for an existing file
  bool operator==(const FileKey&) const = default;
};

[[nodiscard]] inline FileKey file_key(const std::string& path) {
  struct stat info {};
  if (::stat(path.c_str(), &info) == 0) return {info.st_dev, info.st_ino, {}};
  const std::filesystem::path target = final_target(path);
  if (::stat(directory_of(target).c_str(), &info) == 0)
    return {info.st_dev, info.st_ino, target.filename().string()};
  std::error_code error;
  return {0, 0, std::filesystem::weakly_canonical(target, error).string()};
}

}  // namespace detail

/// Throws `IoError` naming both roles when two of `files` (empty paths are skipped) are the
/// same file and at least one of them is written: an output would overwrite an input, or one
/// output the other.
inline void require_distinct_files(const std::vector<FileRole>& files) {
  std::vector<detail::FileKey> keys;
  keys.reserve(files.size());
  for (const FileRole& f : files)
    keys.push_back(f.path.empty() ? detail::FileKey{}
                                  : detail::prefixing_errors(
                                        f.what, [&] { return detail::file_key(f.path); }));
  for (std::size_t i = 0; i < files.size(); ++i) {
    for (std::size_t j = i + 1; j < files.size(); ++j) {
      if (files[i].path.empty() || files[j].path.empty()) continue;
      if (!files[i].output && !files[j].output) continue;
      detail::require<IoError>(!(keys[i] == keys[j]), files[i].what, " '", files[i].path,
                               "' and ", files[j].what, " '", files[j].path,
                               "' are the same file; expected different files (one would ",
                               files[i].output && files[j].output ? "overwrite the other"
                                                                  : "overwrite the input",
                               ")");
    }
  }
}

}  // namespace sbptt
