// libFuzzer target: the states-file parser (sbptt/train/states_io.hpp).
//
// The input is the text of a states file. It goes through `sbptt::parse_states` (double and
// float) with state_dim = the number of comma-separated fields on the first non-blank line
// (the dimension a user would most likely pass), with that + 1 (must be refused), and with
// 0 and -1 (must be refused). Expected outcomes are a matrix or a `sbptt::ParseError`;
// anything else (another exception, a sanitizer report, a broken invariant) is a finding.
//
// Invariants checked on success:
//   * the matrix is state_dim × (number of non-blank lines), and every field of the input is
//     accepted, finite, and has the bits strtod/strtof give for it, in row-major input order;
//   * save_states -> load_states reproduces the matrix bit for bit.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "fuzz_support.hpp"
#include "sbptt/train/states_io.hpp"

namespace {

using sbptt_fuzz::expect;

/// The non-blank lines of the input, split on '\n' (blank = only spaces, tabs and CRs).
std::vector<std::string_view> non_blank_lines(std::string_view text) {
  std::vector<std::string_view> lines;
  std::size_t start = 0;
  while (start < text.size()) {
    std::size_t end = text.find('\n', start);
    if (end == std::string_view::npos) end = text.size();
    const std::string_view line = text.substr(start, end - start);
    if (!sbptt_fuzz::trim(line).empty()) lines.push_back(line);
    start = end + 1;
  }
  return lines;
}

std::vector<std::string_view> fields_of(std::string_view line) {
  std::vector<std::string_view> fields;
  std::size_t start = 0;
  while (true) {
    const std::size_t comma = line.find(',', start);
    if (comma == std::string_view::npos) {
      fields.push_back(line.substr(start));
      return fields;
    }
    fields.push_back(line.substr(start, comma - start));
    start = comma + 1;
  }
}

template <class Scalar>
bool refused(std::string_view text, sbptt::Index state_dim) {
  try {
    (void)sbptt::parse_states<Scalar>(text, state_dim, "fuzz input");
  } catch (const sbptt::ParseError&) {
    return true;
  }
  return false;
}

template <class Scalar>
void check(std::string_view text, const std::vector<std::string_view>& lines,
           const sbptt_fuzz::ScratchDir& scratch) {
  expect(refused<Scalar>(text, 0), "parse_states accepted state_dim = 0");
  expect(refused<Scalar>(text, -1), "parse_states accepted state_dim = -1");
  const auto dim =
      static_cast<sbptt::Index>(lines.empty() ? 1 : fields_of(lines.front()).size());
  expect(refused<Scalar>(text, dim + 1),
         "parse_states accepted a first line with fewer columns than state_dim");

  sbptt::Matrix<Scalar> states;
  try {
    states = sbptt::parse_states<Scalar>(text, dim, "fuzz input");
  } catch (const sbptt::ParseError&) {
    return;
  }

  // Shape, and every value against an independent reading of its field.
  const auto rows = static_cast<sbptt::Index>(lines.size());
  expect(states.rows() == dim, "parse_states: rows != state_dim");
  expect(states.cols() == rows, "parse_states: columns != number of non-blank lines");
  for (sbptt::Index sample = 0; sample < rows; ++sample) {
    const auto fields = fields_of(lines[static_cast<std::size_t>(sample)]);
    expect(static_cast<sbptt::Index>(fields.size()) == dim,
           "parse_states accepted a line with the wrong number of fields");
    for (sbptt::Index r = 0; r < dim; ++r) {
      const Scalar value = states(r, sample);
      expect(std::isfinite(value), "parse_states returned a non-finite value");
      const Scalar reference =
          sbptt_fuzz::reference_value<Scalar>(fields[static_cast<std::size_t>(r)]);
      expect(sbptt_fuzz::same_bits(&value, &reference, 1),
             "parse_states disagrees with strtod/strtof on an accepted field");
    }
  }

  // Round trip through the writer and the file reader.
  const auto file = scratch.file("states.csv");
  sbptt::save_states<Scalar>(file, states);
  const sbptt::Matrix<Scalar> again = sbptt::load_states<Scalar>(file, dim);
  expect(again.rows() == states.rows() && again.cols() == states.cols(),
         "save_states -> load_states changed the shape");
  expect(sbptt_fuzz::same_bits(again.data(), states.data(),
                               static_cast<std::size_t>(states.size())),
         "save_states -> load_states is not bit-identical");
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const sbptt_fuzz::ScratchDir scratch;
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  const std::vector<std::string_view> lines = non_blank_lines(text);
  check<double>(text, lines, scratch);
  check<float>(text, lines, scratch);
  return 0;
}
