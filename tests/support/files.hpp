#pragma once
// Scratch files for tests that write: a fresh directory per process and name, a whole file as
// text, a training log without its wall-time column, and a pipe to read from as a file.
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>
#include <stdexcept>
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

/// A pipe holding `text`, its writing end closed, read through `path()` (/dev/fd/N): what a
/// reader is given for `--init-params <(zcat theta.txt.gz)`. The text must fit in the pipe's
/// buffer (64 KiB on Linux), as it is written whole before anyone reads.
class PipeHolding {
public:
  explicit PipeHolding(const std::string& text) {
    int ends[2];
    if (::pipe(ends) != 0) throw std::runtime_error("PipeHolding: pipe() failed");
    read_end_ = ends[0];
    const bool whole = ::write(ends[1], text.data(), text.size()) ==
                       static_cast<ssize_t>(text.size());
    ::close(ends[1]);
    if (!whole) {
      ::close(read_end_);  // no destructor runs after a throw from here
      throw std::runtime_error("PipeHolding: the text did not fit in the pipe");
    }
  }
  ~PipeHolding() { ::close(read_end_); }
  PipeHolding(const PipeHolding&) = delete;
  PipeHolding& operator=(const PipeHolding&) = delete;
  [[nodiscard]] std::string path() const { return "/dev/fd/" + std::to_string(read_end_); }

private:
  int read_end_ = -1;
};

}  // namespace sbptt::testing
