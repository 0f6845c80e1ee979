#pragma once
// Strict parsing of command-line values: a whole token must be a number, in range, and finite;
// every failure names the flag, the text and what was expected.
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <string_view>
#include <system_error>

#include <sbptt/core/error.hpp>

namespace sbptt::examples {

/// "1e-03" → "0.001", 1e300 → "1e+300": numbers in help texts and messages, as a user
/// would type them (15 significant digits).
[[nodiscard]] inline std::string shown(double value) {
  char text[32];
  std::snprintf(text, sizeof text, "%.15g", value);
  return text;
}

/// Parses `text` as a whole integer in [low, high].
[[nodiscard]] inline long parse_integer(std::string_view flag, std::string_view text, long low,
                                        long high) {
  long value = 0;
  const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
  const bool whole = end == text.data() + text.size();
  if (error == std::errc::result_out_of_range && whole)
    throw InvalidArgument(detail::concat(flag, " ", text, " is out of range; expected an "
                                                          "integer in [", low, ", ", high, "]"));
  if (error != std::errc() || !whole)
    throw InvalidArgument(detail::concat(flag, " '", text, "' is not an integer; expected an "
                                                           "integer in [", low, ", ", high, "]"));
  if (value < low || value > high)
    throw InvalidArgument(detail::concat(flag, " ", value, " is out of range; expected an "
                                                           "integer in [", low, ", ", high, "]"));
  return value;
}

/// Parses `text` as a whole finite number in [low, high] (strtod: accepts 1e-3, rejects
/// trailing text, nan and inf; a value beyond double's range is out of range, not "inf").
[[nodiscard]] inline double parse_number(std::string_view flag, std::string_view text, double low,
                                         double high) {
  const std::string copy(text);
  char* end = nullptr;
  errno = 0;
  const double value = copy.empty() ? 0.0 : std::strtod(copy.c_str(), &end);
  if (copy.empty() || end != copy.c_str() + copy.size())
    throw InvalidArgument(detail::concat(flag, " '", text, "' is not a number; expected a number "
                                                           "in [", shown(low), ", ", shown(high), "]"));
  const bool overflow = errno == ERANGE && std::isinf(value);
  if (overflow || !std::isfinite(value) || value < low || value > high)
    throw InvalidArgument(detail::concat(flag, " ", text, " is out of range; expected a finite "
                                                          "number in [", shown(low), ", ", shown(high), "]"));
  return value;
}

}  // namespace sbptt::examples
