#pragma once
// Strict parsing of command-line values: a whole token must be a number, in range, and finite;
// every failure names the flag, the text and what was expected.
#include <charconv>
#include <cmath>
#include <cstdio>
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

/// "[low, high]", as the help text and the errors of a number flag state its range.
[[nodiscard]] inline std::string range_text(double low, double high) {
  return "[" + shown(low) + ", " + shown(high) + "]";
}

/// `text` without the one leading '+' that the files accept (core/number_text.hpp) and
/// from_chars does not; "++1" and "+-1" keep theirs, and are refused.
[[nodiscard]] inline std::string_view without_plus(std::string_view text) {
  if (text.size() > 1 && text.front() == '+' && text[1] != '-' && text[1] != '+')
    text.remove_prefix(1);
  return text;
}

/// Parses `text` as a whole integer in [low, high] (one leading '+' allowed).
[[nodiscard]] inline long parse_integer(std::string_view flag, std::string_view text, long low,
                                        long high) {
  const std::string_view digits = without_plus(text);
  long value = 0;
  const auto [end, error] = std::from_chars(digits.data(), digits.data() + digits.size(), value);
  const bool whole = end == digits.data() + digits.size();
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

/// Parses `text` as a whole finite decimal number in [low, high], as the files are read
/// (core/number_text.hpp): 1e-3 and one leading '+', but no hexadecimal (strtod took 0x10 for
/// 16), no blanks, nan or inf; a value beyond double's range is out of range, not "inf".
[[nodiscard]] inline double parse_number(std::string_view flag, std::string_view text, double low,
                                         double high) {
  const std::string_view digits = without_plus(text);
  double value = 0;
  const auto [end, error] = std::from_chars(digits.data(), digits.data() + digits.size(), value);
  const bool whole = !digits.empty() && end == digits.data() + digits.size();
  const auto out_of_range = [&] {
    return InvalidArgument(detail::concat(flag, " ", text,
                                          " is out of range; expected a finite number in ",
                                          range_text(low, high)));
  };
  if (error == std::errc::result_out_of_range && whole) throw out_of_range();
  if (error != std::errc() || !whole)
    throw InvalidArgument(detail::concat(flag, " '", text,
                                         "' is not a number; expected a number in ",
                                         range_text(low, high)));
  if (!std::isfinite(value) || value < low || value > high) throw out_of_range();
  return value;
}

}  // namespace sbptt::examples
