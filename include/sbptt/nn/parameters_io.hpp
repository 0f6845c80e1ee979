#pragma once
/// \file The parameters file (docs/formats.md): plain text, one number per line, in flat-vector order.
///
/// Numbers are written as printf `%.17g` for double and `%.9g` for float, the shortest fixed
/// precision that round-trips every value bit for bit (core/number_text.hpp).
///
/// Loading is strict, because a silently misread controller is worse than a refused one:
/// each line is one finite number with optional surrounding blanks (spaces, tabs, a CR from a
/// Windows editor), ended by a newline (without one, the last number may be a cut copy's);
/// anything else is a `ParseError` naming the file, the 1-based line and the text. Writing
/// goes to a temporary file beside the target, renamed over it at the end, so a crash never
/// leaves a half-written parameters file.
#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>
#include <vector>

#include "sbptt/core/atomic_file.hpp"
#include "sbptt/core/concepts.hpp"
#include "sbptt/core/number_text.hpp"
#include "sbptt/core/error.hpp"
#include "sbptt/core/input_file.hpp"
#include "sbptt/core/non_finite.hpp"
#include "sbptt/core/types.hpp"

namespace sbptt {

/// Writes θ to `path`, one number per line (%.17g for double, %.9g for float).
/// \param theta  the flat parameter vector, any length
/// Throws `NonFiniteError` (naming the index) before writing anything if θ has a NaN or Inf,
/// and `IoError` if the temporary file cannot be written or renamed.
template <class Scalar>
void save_parameters(const std::filesystem::path& path, const Vector<Scalar>& theta) {
  for (Index i = 0; i < theta.size(); ++i)
    if (!std::isfinite(theta(i)))
      throw NonFiniteError(detail::concat("save_parameters: parameter ", i, " is ",
                                          detail::value_text(static_cast<double>(theta(i))),
                                          ", expected a finite number"));
  std::string text;
  for (Index i = 0; i < theta.size(); ++i) {
    detail::append_number(text, theta(i));
    text += '\n';
  }
  write_file_atomically(path.string(), text);
}

/// Reads a parameters file that must hold exactly `expected` numbers, one per line (blank lines
/// at the end are ignored; one between numbers is refused, unlike in states files).
/// \return the flat parameter vector, `expected` entries
/// Throws `IoError` if `path` cannot be read (with the system's reason), `ParseError` for a
/// malformed line or a wrong count ("expected N numbers, got M"). Reading is bounded: a line
/// longer than a number can be, or a number beyond the `expected`-th, is refused at once,
/// without reading the rest of the file.
template <class Scalar>
[[nodiscard]] Vector<Scalar> load_parameters(const std::filesystem::path& path, Index expected) {
  std::ifstream in = detail::open_for_reading(path, "load_parameters: ", "a parameters file");
  std::vector<Scalar> values;
  values.reserve(static_cast<std::size_t>(expected > 0 ? expected : 0));
  std::string line;
  Index line_number = 0, blank_run_start = 0;
  const std::string file = detail::concat("parameters file '", path.string(), "'");
  const auto where = [&] { return detail::concat(file, ", line ", line_number); };
  while (true) {
    const detail::LineRead read =
        detail::read_bounded_line(*in.rdbuf(), line, detail::max_number_chars, file);
    if (read == detail::LineRead::End) break;
    ++line_number;
    detail::require<ParseError>(read != detail::LineRead::TooLong, where(), ": longer than ",
                                detail::max_number_chars, " characters (it starts '",
                                detail::printable(line), "'); expected one number per line");
    if (detail::trim_blanks(line).empty()) {  // allowed only at the end of the file
      if (blank_run_start == 0) blank_run_start = line_number;
      continue;
    }
    detail::require<ParseError>(blank_run_start == 0, "parameters file '", path.string(),
                                "', line ", blank_run_start,
                                ": empty, expected one number");
    detail::require<ParseError>(static_cast<Index>(values.size()) < expected, where(),
                                ": more than the ", expected, " numbers expected");
    values.push_back(detail::parse_finite<Scalar>(line, where()));
    detail::require_line_ended(read, line, where());  // after the line's own errors
  }
  detail::require<IoError>(!in.bad(), "load_parameters: reading '", path.string(),
                           "' failed after line ", line_number);
  const auto count = static_cast<Index>(values.size());
  detail::require<ParseError>(count == expected, "parameters file '", path.string(),
                              "': expected ", expected, " numbers, got ", count);
  return Eigen::Map<const Vector<Scalar>>(values.data(), count);
}

/// Saves a controller's parameters (see `save_parameters(path, theta)`).
template <Controller Ctrl>
void save_parameters(const std::filesystem::path& path, const Ctrl& controller) {
  save_parameters<typename Ctrl::Scalar>(path, controller.params());
}

/// Loads `path` into a controller; the file must hold exactly num_params() numbers. On any
/// error the controller is left unchanged.
template <Controller Ctrl>
void load_parameters(const std::filesystem::path& path, Ctrl& controller) {
  controller.params() = load_parameters<typename Ctrl::Scalar>(path, controller.num_params());
}

}  // namespace sbptt
