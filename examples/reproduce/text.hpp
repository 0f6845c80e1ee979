// reproduce: small text helpers (number formats, lists, whole-file reads).
#pragma once

#include <algorithm>
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

#include "flag_values.hpp"

namespace fs = std::filesystem;

namespace reproduce {

using sbptt::InvalidArgument;
using sbptt::detail::concat;
using sbptt::examples::parse_integer;
using sbptt::examples::parse_number;

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

inline std::string read_text(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return {};
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

}  // namespace reproduce
