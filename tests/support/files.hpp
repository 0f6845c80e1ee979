#pragma once
// Scratch files for tests that write: a fresh directory per process and name, a whole file as
// text, and a training log without its wall-time column.
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>
#include <string>

namespace sbptt::testing {

/// An empty directory `<tmp>/sbptt_<pid>/<name>` (emptied if it was there).
inline std::filesystem::path fresh_directory(const std::string& name) {
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("sbptt_" + std::to_string(getpid())) / name;
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

inline std::string file_text(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), {}};
}

/// A training log without its last column (seconds is wall time, the one field that differs
/// between two runs of the same settings).
inline std::string without_seconds(const std::string& csv) {
  std::string out;
  std::istringstream in(csv);
  for (std::string line; std::getline(in, line);) out += line.substr(0, line.rfind(',')) + "\n";
  return out;
}

}  // namespace sbptt::testing
