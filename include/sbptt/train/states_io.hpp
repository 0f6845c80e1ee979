#pragma once
/// \file The states file (docs/formats.md): CSV without header, one sample per row, the
/// simulator's State layout, numbers in round-trip precision. In memory a set of states is a
/// state_dim × N matrix (one sample per column).
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>
#include <vector>

#include "sbptt/core/atomic_file.hpp"
#include "sbptt/core/input_file.hpp"
#include "sbptt/core/number_text.hpp"
#include "sbptt/core/types.hpp"

namespace sbptt {

namespace detail {

/// Appends the `state_dim` numbers of one states-file row (`line`, without its newline) to
/// `values`; `where` names the file and line in errors. A blank line appends nothing and
/// returns false.
template <class Scalar>
bool parse_state_row(std::string_view line, Index state_dim, const std::string& where,
                     std::vector<Scalar>& values) {
  if (trim_blanks(line).empty()) return false;
  Index columns = 0;
  std::size_t field_start = 0;
  while (true) {
    const std::size_t comma = line.find(',', field_start);
    const std::string_view field = line.substr(
        field_start, comma == std::string_view::npos ? std::string_view::npos : comma - field_start);
    ++columns;
    require<ParseError>(columns <= state_dim, where, ": more than ", state_dim,
                        " columns; expected exactly state_dim = ", state_dim);
    values.push_back(parse_finite<Scalar>(field, concat(where, ", column ", columns)));
    if (comma == std::string_view::npos) break;
    field_start = comma + 1;
  }
  require<ParseError>(columns == state_dim, where, ": ", columns,
                      " columns; expected exactly state_dim = ", state_dim);
  return true;
}

/// state_dim × rows from the row-major `values`; throws when there is no row.
template <class Scalar>
Matrix<Scalar> states_matrix(const std::vector<Scalar>& values, Index state_dim, Index rows,
                             const std::string& name) {
  require<ParseError>(rows > 0, "states file '", name,
                      "' holds no samples; expected at least one row of ", state_dim, " numbers");
  return Eigen::Map<const Matrix<Scalar>>(values.data(), state_dim, rows);
}

}  // namespace detail

/// Parses states-file text (`name` names the source in errors). Every row must hold exactly
/// `state_dim` finite numbers; blank lines are skipped; returns state_dim × rows.
template <class Scalar>
[[nodiscard]] Matrix<Scalar> parse_states(std::string_view text, Index state_dim,
                                          const std::string& name) {
  std::vector<Scalar> values;
  Index rows = 0, line_number = 0;
  std::size_t start = 0;
  while (start < text.size()) {
    std::size_t end = text.find('\n', start);
    if (end == std::string_view::npos) end = text.size();
    const std::string_view line = text.substr(start, end - start);
    start = end + 1;
    ++line_number;
    if (detail::parse_state_row(line, state_dim,
                                detail::concat("states file '", name, "', line ", line_number),
                                values))
      ++rows;
  }
  return detail::states_matrix(values, state_dim, rows, name);
}

/// Reads a states file; throws IoError if unreadable (with the system's reason), ParseError if
/// malformed, or if its last row has no newline after it (a copy cut inside a number). Reading
/// is bounded: a line longer than `state_dim` numbers can be is refused as soon as it is,
/// without reading the rest.
template <class Scalar>
[[nodiscard]] Matrix<Scalar> load_states(const std::filesystem::path& path, Index state_dim) {
  std::ifstream in = detail::open_for_reading(path, "load_states: ", "a CSV file of states");
  const auto longest = static_cast<std::size_t>(state_dim) * (detail::max_number_chars + 1);
  std::vector<Scalar> values;
  std::string line;
  Index rows = 0, line_number = 0;
  const std::string file = detail::concat("states file '", path.string(), "'");
  while (true) {
    const detail::LineRead read = detail::read_bounded_line(*in.rdbuf(), line, longest, file);
    if (read == detail::LineRead::End) break;
    ++line_number;
    const std::string where = detail::concat(file, ", line ", line_number);
    detail::require<ParseError>(read != detail::LineRead::TooLong, where, ": longer than ",
                                longest, " characters (it starts '", detail::printable(line),
                                "'); expected a row of ", state_dim, " numbers");
    if (detail::parse_state_row(line, state_dim, where, values)) ++rows;
    detail::require_line_ended(read, line, where);  // after the row's own errors
  }
  detail::require<IoError>(!in.bad(), "reading states file '", path.string(),
                           "' failed after line ", line_number);
  return detail::states_matrix(values, state_dim, rows, path.string());
}

/// Writes `states` (state_dim × N) as a states file, atomically.
template <class Scalar>
void save_states(const std::filesystem::path& path, const Matrix<Scalar>& states) {
  std::string text;
  for (Index b = 0; b < states.cols(); ++b) {
    for (Index r = 0; r < states.rows(); ++r) {
      if (r > 0) text += ',';
      detail::append_number(text, states(r, b));
    }
    text += '\n';
  }
  write_file_atomically(path.string(), text);
}

}  // namespace sbptt
