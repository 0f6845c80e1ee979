#pragma once
/// \file The states file (DESIGN §4): CSV without header, one sample per row, the
/// simulator's State layout, numbers in round-trip precision. In memory a set of states is a
/// state_dim × N matrix (one sample per column).
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "sbptt/core/atomic_file.hpp"
#include "sbptt/core/number_text.hpp"
#include "sbptt/core/types.hpp"

namespace sbptt {

/// Parses states-file text (`name` names the source in errors). Every row must hold exactly
/// `state_dim` finite numbers; returns state_dim × rows.
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
    if (detail::trim_blanks(line).empty()) continue;
    const std::string where = detail::concat("states file '", name, "', line ", line_number);
    Index columns = 0;
    std::size_t field_start = 0;
    while (true) {
      const std::size_t comma = line.find(',', field_start);
      const std::string_view field = line.substr(
          field_start, comma == std::string_view::npos ? std::string_view::npos : comma - field_start);
      ++columns;
      detail::require<ParseError>(columns <= state_dim, where, ": more than ", state_dim,
                                  " columns; expected exactly state_dim = ", state_dim);
      values.push_back(detail::parse_finite<Scalar>(
          field, detail::concat(where, ", column ", columns)));
      if (comma == std::string_view::npos) break;
      field_start = comma + 1;
    }
    detail::require<ParseError>(columns == state_dim, where, ": ", columns,
                                " columns; expected exactly state_dim = ", state_dim);
    ++rows;
  }
  detail::require<ParseError>(rows > 0, "states file '", name,
                              "' holds no samples; expected at least one row of ", state_dim,
                              " numbers");
  return Eigen::Map<const Matrix<Scalar>>(values.data(), state_dim, rows);
}

/// Reads a states file; throws IoError if unreadable, ParseError if malformed.
template <class Scalar>
[[nodiscard]] Matrix<Scalar> load_states(const std::filesystem::path& path, Index state_dim) {
  std::error_code error;
  detail::require<IoError>(!std::filesystem::is_directory(path, error), "states file '",
                           path.string(), "' is a directory; expected a CSV file");
  std::ifstream in(path, std::ios::binary);
  detail::require<IoError>(static_cast<bool>(in), "cannot open states file '", path.string(),
                           "' for reading");
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  return parse_states<Scalar>(text, state_dim, path.string());
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
