#pragma once
// Walks `--flag value` / `--flag=value` / `--switch` tokens. Only the reproduction runner still
// uses it; every other program reads its flags through CommandLine (command_line.hpp, CLI11).
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <sbptt/core/error.hpp>

namespace sbptt::examples {

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

}  // namespace sbptt::examples
