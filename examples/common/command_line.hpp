#pragma once
// The command line of every example program, on CLI11: `--help` lists each flag with its
// meaning, default and range, and every bad flag or value becomes an sbptt::InvalidArgument
// that names the flag, the value and what was expected (the programs exit 2 on it).
//
// CLI11 reads the tokens; the values are converted by parse_integer / parse_number
// (flag_values.hpp), so that "--epochs ten" and "--poles 9" are refused in the same words by
// every program, and unknown flags and missing values are reported in those words too.
#include <algorithm>
#include <cstdio>
#include <functional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <CLI/CLI.hpp>

#include "write_signals.hpp"
#include "flag_values.hpp"

namespace sbptt::examples {

class CommandLine {
public:
  CommandLine(std::string program, std::string description)
      : app_(std::move(description), std::move(program)) {
    ignore_write_signals();
    app_.allow_extras();  // unknown flags are reported by parse(), in the words of the others
    app_.option_defaults()->multi_option_policy(CLI::MultiOptionPolicy::TakeLast);
    app_.set_help_flag("--help", "print every flag with its meaning, default and range; exit");
    switches_.emplace_back("--help");
    app_.get_formatter()->column_width(40);
  }

  /// A flag taking a value that `set` converts (and throws InvalidArgument on); a message that
  /// does not start with the flag gets it in front.
  CLI::Option* value(const std::string& flag, const std::string& type_name,
                     const std::string& meaning, const std::string& default_shown,
                     std::function<void(const std::string&)> set) {
    // The library's parsers (parse_method, parse_clip_mode) cannot know which flag they read.
    auto named = [flag, set = std::move(set)](const std::string& text) {
      try {
        set(text);
      } catch (const InvalidArgument& e) {
        if (std::string_view(e.what()).starts_with(flag)) throw;
        throw InvalidArgument(detail::concat(flag, ": ", e.what()));
      }
    };
    CLI::Option* option = app_.add_option_function<std::string>(flag, named, meaning);
    option->type_name(type_name);
    values_.push_back({flag, option, std::move(named)});
    if (!default_shown.empty()) option->default_str(default_shown);
    return option;
  }

  /// An integer flag in [low, high]; `target` holds the default.
  template <class Integer>
  CLI::Option* integer(const std::string& flag, Integer& target, long low, long high,
                       const std::string& meaning) {
    return value(flag, "N", detail::concat(meaning, "; an integer in [", low, ", ", high, "]"),
                 std::to_string(target), [&target, flag, low, high](const std::string& text) {
                   target = static_cast<Integer>(parse_integer(flag, text, low, high));
                 });
  }

  /// A finite number flag in [low, high]; `target` holds the default.
  CLI::Option* number(const std::string& flag, double& target, double low, double high,
                      const std::string& meaning) {
    return value(flag, "X",
                 detail::concat(meaning, "; a number in ", range_text(low, high)),
                 shown(target), [&target, flag, low, high](const std::string& text) {
                   target = parse_number(flag, text, low, high);
                 });
  }

  /// A file path; an empty value (e.g. an unset shell variable) is refused, not ignored.
  CLI::Option* path(const std::string& flag, std::string& target, const std::string& meaning,
                    const std::string& default_shown = "none") {
    return value(flag, "FILE", meaning, default_shown, [&target, flag](const std::string& text) {
      if (text.empty())
        throw InvalidArgument(detail::concat(flag, " '' is an empty path; expected a path "
                                                   "(an unset shell variable?)"));
      target = text;
    });
  }

  /// A switch without value; `set` runs when it is given. `parse` refuses "--switch=value",
  /// which CLI11 would read as on or off.
  CLI::Option* flag(const std::string& flag, const std::string& meaning, std::function<void()> set) {
    switches_.push_back(flag);
    return app_.add_flag_callback(flag, std::move(set), meaning);
  }

  /// A flag this program refuses with `reason` (not listed by --help).
  void refuse(const std::string& flag, const std::string& reason) {
    refused_.emplace_back(flag, reason);
  }

  /// Reads argv. Returns false after printing the help on stdout (the program exits 0);
  /// throws InvalidArgument for an unknown flag, a missing value or a bad value, with --help
  /// too.
  bool parse(int argc, const char* const* argv) {
    for (int i = 1; i < argc; ++i) {
      const std::string token = argv[i];
      // CLI11 takes the word after a flag as its value even when it is another flag.
      if (i + 1 < argc && takes_value(token) && std::string_view(argv[i + 1]).starts_with("--"))
        throw InvalidArgument(detail::concat(token, " needs a value; the next word, '",
                                             argv[i + 1], "', is a flag (a value that starts "
                                             "with -- is written ", token, "=VALUE)"));
      // CLI11 reads "--flag=" as "--flag" and takes the next word too.
      if (token.ends_with('=') && takes_value(token.substr(0, token.size() - 1))) {
        const std::string flag = token.substr(0, token.size() - 1);
        throw InvalidArgument(detail::concat(flag, " needs a value; '", token, "' gives none "
                                             "(expected ", flag, "=VALUE or ", flag, " VALUE)"));
      }
      for (const auto& [flag, reason] : refused_)
        if (token == flag || token.rfind(flag + "=", 0) == 0)
          throw InvalidArgument(detail::concat(flag, ": ", reason));
      for (const std::string& flag : switches_)
        if (token.rfind(flag + "=", 0) == 0)
          throw InvalidArgument(detail::concat(token, ": ", flag, " is a switch and takes no "
                                               "value; expected ", flag, " alone"));
    }
    try {
      app_.parse(argc, argv);
    } catch (const CLI::CallForHelp&) {
      // CLI11 calls for help before it reports the extras; a typo beside --help is still one.
      refuse_extras();
      std::fputs(app_.help().c_str(), stdout);
      return false;
    } catch (const CLI::ArgumentMismatch& e) {
      // "--rc: 1 required X missing": the flag came last (one followed by a flag is refused
      // above).
      const std::string what = e.what();
      if (what.find(" required ") != std::string::npos && what.find(" missing") != std::string::npos)
        throw InvalidArgument(detail::concat(what.substr(0, what.find(':')),
                                             " needs a value; none was given"));
      throw InvalidArgument(what);
    } catch (const CLI::ParseError& e) {
      throw InvalidArgument(e.what());
    }
    refuse_extras();
    // A flag given twice takes its last value, which CLI11 alone reads: the earlier ones are
    // read too, in order, so that a bad one is refused as it would be alone.
    for (const ValueFlag& value : values_)
      if (value.option->count() > 1)
        for (const std::string& text : value.option->results()) value.set(text);
    return true;
  }

  /// Whether `token` is exactly the name of a flag that takes a value.
  [[nodiscard]] bool takes_value(const std::string& token) const {
    return std::any_of(values_.begin(), values_.end(),
                       [&](const ValueFlag& value) { return value.flag == token; });
  }

  /// Whether `flag` was given on the command line (after parse).
  [[nodiscard]] bool given(const std::string& flag) const { return app_.count(flag) > 0; }

  /// The flags this program accepts, comma-separated.
  [[nodiscard]] std::string accepted() const {
    std::string list;
    for (const CLI::Option* option : app_.get_options()) {
      if (option->get_group().empty() || option->get_name() == "--help") continue;
      list += (list.empty() ? "" : ", ") + option->get_name();
    }
    return list;
  }

private:
  /// Throws for the first word of argv that is no flag of this program.
  void refuse_extras() const {
    const std::vector<std::string> extras = app_.remaining();
    if (extras.empty()) return;
    const std::string& first = extras.front();
    if (first.rfind('-', 0) != 0)
      throw InvalidArgument(detail::concat("unexpected argument '", first,
                                           "'; expected a flag starting with --"));
    throw InvalidArgument(detail::concat("unknown flag '", first.substr(0, first.find('=')),
                                         "'; accepted flags: ", accepted(),
                                         " (--help explains each)"));
  }

  CLI::App app_;
  std::vector<std::pair<std::string, std::string>> refused_;
  std::vector<std::string> switches_;
  struct ValueFlag {
    std::string flag;
    CLI::Option* option;
    std::function<void(const std::string&)> set;  ///< converts and stores one value
  };
  std::vector<ValueFlag> values_;
};

}  // namespace sbptt::examples
