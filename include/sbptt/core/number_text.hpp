#pragma once
/// \file Exact number ↔ text conversion for the interchange files (DESIGN §4).
///
/// `std::to_chars` / `std::from_chars` give the printf `%.17g` (double) or `%.9g` (float)
/// strings and exact round-trips, but ignore the global C locale (printf would write "0,5"
/// under a German locale). Parsing is strict: one finite number, optional surrounding blanks
/// (spaces, tabs, a CR from a Windows editor), nothing else.
#include <charconv>
#include <cmath>
#include <string>
#include <string_view>
#include <system_error>
#include <type_traits>

#include "sbptt/core/error.hpp"

namespace sbptt::detail {

/// Significant digits that make `Scalar` round-trip through decimal text (%.17g / %.9g).
template <class Scalar>
inline constexpr int round_trip_digits = std::is_same_v<Scalar, float> ? 9 : 17;

[[nodiscard]] inline std::string_view trim_blanks(std::string_view text) {
  const auto blank = [](char c) { return c == ' ' || c == '\t' || c == '\r'; };
  while (!text.empty() && blank(text.front())) text.remove_prefix(1);
  while (!text.empty() && blank(text.back())) text.remove_suffix(1);
  return text;
}

/// Parses one finite number; `where` prefixes every error ("file 'p', line 3").
template <class Scalar>
[[nodiscard]] Scalar parse_finite(std::string_view field, const std::string& where) {
  const std::string_view text = trim_blanks(field);
  require<ParseError>(!text.empty(), where, ": empty, expected one number");
  std::string_view digits = text;
  // from_chars rejects a leading '+', which other writers may emit; accept exactly one.
  if (digits.size() > 1 && digits.front() == '+' && digits[1] != '-' && digits[1] != '+')
    digits.remove_prefix(1);
  Scalar value{};
  const auto [end, error] = std::from_chars(digits.data(), digits.data() + digits.size(), value);
  require<ParseError>(error != std::errc::invalid_argument, where, ": '", text,
                      "' is not a number");
  require<ParseError>(error != std::errc::result_out_of_range, where, ": '", text,
                      "' is out of range for the scalar type");
  require<ParseError>(end == digits.data() + digits.size(), where, ": trailing characters '",
                      std::string_view(end, static_cast<std::size_t>(
                                                digits.data() + digits.size() - end)),
                      "' after the number in '", text, "'");
  require<ParseError>(std::isfinite(value), where, ": '", text,
                      "' is not finite, expected a finite number");
  return value;
}

/// Appends `value` in round-trip precision to `out`.
template <class Scalar>
void append_number(std::string& out, Scalar value) {
  char buffer[64];
  const auto result = std::to_chars(buffer, buffer + sizeof buffer, value,
                                    std::chars_format::general, round_trip_digits<Scalar>);
  out.append(buffer, result.ptr);
}

}  // namespace sbptt::detail
