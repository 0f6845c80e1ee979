// reproduce: small text helpers (number formats, lists, whole-file reads).
#pragma once

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include <sbptt/core/error.hpp>

#include "flag_values.hpp"

namespace fs = std::filesystem;

namespace reproduce {

using sbptt::InvalidArgument;
using sbptt::detail::concat;
using sbptt::examples::parse_integer;
using sbptt::examples::parse_number;

/// "1 run", "2 runs": a count and its noun.
inline std::string count_of(std::size_t count, const std::string& noun) {
  return concat(count, " ", noun, count == 1 ? "" : "s");
}

inline std::string format_number(double value) {
  char text[64];
  std::snprintf(text, sizeof text, "%g", value);
  return text;
}

inline std::string format_exact(double value) {
  char text[64];
  std::snprintf(text, sizeof text, "%.17g", value);
  return text;
}

inline std::string format_duration(double seconds) {
  const long s = std::lround(std::max(0.0, seconds));
  char text[64];
  if (s >= 3600) std::snprintf(text, sizeof text, "%ldh%02ldm", s / 3600, (s / 60) % 60);
  else if (s >= 60) std::snprintf(text, sizeof text, "%ldm%02lds", s / 60, s % 60);
  else std::snprintf(text, sizeof text, "%lds", s);
  return text;
}

inline std::vector<std::string> split(const std::string& text, char separator) {
  std::vector<std::string> parts;
  std::string part;
  std::istringstream in(text);
  while (std::getline(in, part, separator)) parts.push_back(part);
  if (!text.empty() && text.back() == separator) parts.emplace_back();
  return parts;
}

/// A comma-separated flag value: no empty items.
inline std::vector<std::string> parse_list(const std::string& flag, const std::string& text) {
  std::vector<std::string> items = split(text, ',');
  if (items.empty()) throw InvalidArgument(concat(flag, " needs a comma-separated list; got ''"));
  for (const auto& item : items)
    if (item.empty())
      throw InvalidArgument(concat(flag, " '", text, "' has an empty item; expected a list "
                                                     "like a,b,c"));
  return items;
}

inline bool same_number(double a, double b) {
  return std::abs(a - b) <= 1e-9 * std::max(std::abs(a), std::abs(b));
}

/// The whole of the regular file `path`, or "" when there is none. Anything else under the
/// name (a named pipe, a device, a folder) reads as "" too: opening a pipe to read waits for a
/// writer for ever, and the runner's own files are never one.
inline std::string read_text(const fs::path& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) return {};
  std::string text;
  struct stat info {};
  if (::fstat(fd, &info) == 0 && S_ISREG(info.st_mode)) {
    char buffer[65536];
    ssize_t got = 0;
    while ((got = ::read(fd, buffer, sizeof buffer)) > 0 ||
           (got < 0 && errno == EINTR))
      if (got > 0) text.append(buffer, static_cast<std::size_t>(got));
  }
  ::close(fd);
  return text;
}

}  // namespace reproduce
