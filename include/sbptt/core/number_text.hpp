#pragma once
/// \file Exact number ↔ text conversion for the interchange files (docs/formats.md), and the
/// bounded line reader their loaders share.
///
/// `std::to_chars` / `std::from_chars` give the printf `%.17g` (double) or `%.9g` (float)
/// strings and exact round-trips, but ignore the global C locale (printf would write "0,5"
/// under a German locale). Parsing is strict: one finite number, optional surrounding blanks
/// (spaces, tabs, a CR from a Windows editor), nothing else.
#include <charconv>
#include <cmath>
#include <cstdio>
#include <ios>
#include <streambuf>
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

/// The longest field a number of our files can need: a sign, 17 significant digits, a point
/// and an exponent such as e-308 are 25 characters; the rest allows blanks around it.
inline constexpr std::size_t max_number_chars = 64;

/// `text` as it may be shown in a message: at most `max_chars` characters, every byte that is
/// not printable ASCII written as \xNN, so that a binary file is never echoed to a terminal.
[[nodiscard]] inline std::string printable(std::string_view text, std::size_t max_chars = 40) {
  std::string shown;
  for (std::size_t i = 0; i < text.size() && i < max_chars; ++i) {
    const auto byte = static_cast<unsigned char>(text[i]);
    if (byte >= 0x20 && byte < 0x7f) {
      shown += static_cast<char>(byte);
    } else {
      char escaped[8];
      std::snprintf(escaped, sizeof escaped, "\\x%02x", static_cast<unsigned>(byte));
      shown += escaped;
    }
  }
  if (text.size() > max_chars) shown += "...";
  return shown;
}

/// What `read_bounded_line` found. `Unended` is a last line with no '\n' after it: every
/// file the library writes ends its lines, so in one of them such a line is where a copy was
/// cut short, possibly inside a number.
enum class LineRead { Line, Unended, End, TooLong };

/// Reads one line (without its '\n') of at most `max_chars` characters into `line`. Returns
/// End at the end of the input, TooLong as soon as the line exceeds `max_chars` (the rest is
/// never read, so a file without newlines such as /dev/zero costs at most `max_chars`).
/// `file` names the file in the `IoError` of a failed read: libstdc++'s file buffer throws its
/// own words for it ("basic_filebuf::underflow error reading the file"), without the file.
[[nodiscard]] inline LineRead read_bounded_line(std::streambuf& in, std::string& line,
                                                std::size_t max_chars, const std::string& file) {
  line.clear();
  using Traits = std::streambuf::traits_type;
  try {
    auto c = in.sbumpc();
    if (Traits::eq_int_type(c, Traits::eof())) return LineRead::End;
    while (!Traits::eq_int_type(c, Traits::eof()) && Traits::to_char_type(c) != '\n') {
      if (line.size() == max_chars) return LineRead::TooLong;
      line += Traits::to_char_type(c);
      c = in.sbumpc();
    }
    if (Traits::eq_int_type(c, Traits::eof())) return LineRead::Unended;
  } catch (const std::ios_base::failure& e) {
    throw IoError(concat("reading ", file, " failed: ", e.what()));
  }
  return LineRead::Line;
}

/// Refuses a non-blank last line that `read_bounded_line` found `Unended`; `where` names the
/// file and line.
inline void require_line_ended(LineRead read, std::string_view line, const std::string& where) {
  require<ParseError>(read != LineRead::Unended || trim_blanks(line).empty(), where, ": '",
                      printable(line), "' has no newline at its end, so the file may have been",
                      " cut short; expected every line to end with one, as sbptt writes them",
                      " (add one if you wrote the file by hand)");
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
  require<ParseError>(error != std::errc::invalid_argument, where, ": '", printable(text),
                      "' is not a number");
  require<ParseError>(error != std::errc::result_out_of_range, where, ": '", printable(text),
                      "' is out of range for the scalar type");
  require<ParseError>(end == digits.data() + digits.size(), where, ": trailing characters '",
                      printable(std::string_view(end, static_cast<std::size_t>(
                                                          digits.data() + digits.size() - end))),
                      "' after the number in '", printable(text), "'");
  require<ParseError>(std::isfinite(value), where, ": '", printable(text),
                      "' is not finite, expected a finite number");
  return value;
}

/// Appends `value` as printf would in the "C" locale with `format` and `precision` (general:
/// %.<precision>g, fixed: %.<precision>f), whatever the process's locale. The buffer holds any
/// double in fixed format with up to 8 decimals (a sign, 309 digits, a point).
template <class Scalar>
void append_formatted(std::string& out, Scalar value, std::chars_format format, int precision) {
  char buffer[320];
  const auto result = std::to_chars(buffer, buffer + sizeof buffer, value, format, precision);
  require(result.ec == std::errc(), "append_formatted: ", value, " does not fit ", sizeof buffer,
          " characters with precision ", precision);
  out.append(buffer, result.ptr);
}

/// Appends `value` in round-trip precision to `out`.
template <class Scalar>
void append_number(std::string& out, Scalar value) {
  append_formatted(out, value, std::chars_format::general, round_trip_digits<Scalar>);
}

/// The shortest text that reads back to `value` ("2e+10", "0.005", "nan", "-inf").
[[nodiscard]] inline std::string shortest(double value) {
  char buffer[32];
  const auto result = std::to_chars(buffer, buffer + sizeof buffer, value);
  return std::string(buffer, result.ptr);
}

/// `text` in the shortest form that reads back to the same double, where `text` is that
/// double's round-trip form as `append_number` writes it ("0.0050000000000000001" is "0.005"
/// for a reader); any other text as it is.
[[nodiscard]] inline std::string shortest_if_round_trip(const std::string& text) {
  double value = 0;
  const char* end = text.data() + text.size();
  const auto parsed = std::from_chars(text.data(), end, value);
  if (parsed.ec != std::errc() || parsed.ptr != end || !std::isfinite(value)) return text;
  std::string round_trip;
  append_number(round_trip, value);
  return round_trip == text ? shortest(value) : text;
}

}  // namespace sbptt::detail
