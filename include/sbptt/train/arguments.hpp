#pragma once
/// \file Strict parsing of command-line values: a whole token must be a number, in range, and
/// finite; every failure names the flag, the text and what was expected.
#include <charconv>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <optional>
#include <string>
#include <string_view>
#include <system_error>
#include <utility>
#include <vector>

#include "sbptt/core/error.hpp"

namespace sbptt {

/// Parses `text` as a whole integer in [low, high].
[[nodiscard]] inline long parse_integer(std::string_view flag, std::string_view text, long low,
                                        long high) {
  long value = 0;
  const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (error != std::errc() || end != text.data() + text.size())
    throw InvalidArgument(detail::concat(flag, " '", text, "' is not an integer; expected an "
                                                           "integer in [", low, ", ", high, "]"));
  if (value < low || value > high)
    throw InvalidArgument(detail::concat(flag, " ", value, " is out of range; expected an "
                                                           "integer in [", low, ", ", high, "]"));
  return value;
}

/// Parses `text` as a whole finite number in [low, high] (strtod: accepts 1e-3, rejects
/// trailing text, nan and inf).
[[nodiscard]] inline double parse_number(std::string_view flag, std::string_view text, double low,
                                         double high) {
  const std::string copy(text);
  char* end = nullptr;
  const double value = copy.empty() ? 0.0 : std::strtod(copy.c_str(), &end);
  if (copy.empty() || end != copy.c_str() + copy.size())
    throw InvalidArgument(detail::concat(flag, " '", text, "' is not a number; expected a number "
                                                           "in [", low, ", ", high, "]"));
  if (!std::isfinite(value) || value < low || value > high)
    throw InvalidArgument(detail::concat(flag, " ", text, " is out of range; expected a finite "
                                                          "number in [", low, ", ", high, "]"));
  return value;
}

/// Walks `--flag value` / `--flag=value` / `--switch` tokens.
class ArgumentCursor {
public:
  ArgumentCursor(int argc, const char* const* argv) : tokens_(argv + 1, argv + argc) {}

  /// Advances to the next flag; false at the end. Throws on a token that is not a flag.
  bool next() {
    if (index_ >= tokens_.size()) return false;
    std::string token = tokens_[index_++];
    if (token.rfind("--", 0) != 0)
      throw InvalidArgument(detail::concat("unexpected argument '", token,
                                           "'; expected a flag starting with --"));
    inline_value_.reset();
    if (const auto eq = token.find('='); eq != std::string::npos) {
      inline_value_ = token.substr(eq + 1);
      token.resize(eq);
    }
    flag_ = token;
    return true;
  }

  [[nodiscard]] const std::string& flag() const { return flag_; }

  /// The value of the current flag (the `=` part or the next token).
  std::string value() {
    if (inline_value_) return *std::exchange(inline_value_, std::nullopt);
    if (index_ >= tokens_.size())
      throw InvalidArgument(detail::concat(flag_, " needs a value; none was given"));
    return tokens_[index_++];
  }

  /// Throws for a switch given a value (`--double=1`).
  void no_value() const {
    if (inline_value_)
      throw InvalidArgument(detail::concat(flag_, " takes no value; got '", *inline_value_, "'"));
  }

  [[noreturn]] void unknown(std::string_view accepted) const {
    throw InvalidArgument(detail::concat("unknown flag '", flag_, "'; accepted flags: ", accepted));
  }

private:
  std::vector<std::string> tokens_;
  std::size_t index_ = 0;
  std::string flag_;
  std::optional<std::string> inline_value_;
};

}  // namespace sbptt
