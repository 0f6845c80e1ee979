// libFuzzer target: the parameters-file parser (sbptt/nn/parameters_io.hpp).
//
// The input is the text of a parameters file. Every line goes through the line parser
// `sbptt::detail::parse_finite` (double and float); the whole input, written to a scratch
// file, goes through `sbptt::load_parameters` (double and float). Expected outcomes are a
// value or a `sbptt::ParseError`; anything else (another exception, a sanitizer report, a
// broken invariant) is a finding.
//
// Invariants checked:
//   * an accepted line is finite and has the bits strtod/strtof give for it;
//   * load_parameters(path, n) succeeds iff every line is accepted (and at most
//     max_number_chars long, the format's line bound), the last one is ended by a newline
//     (without one it may be a cut copy's), and n is the line count (std::getline's count: a
//     final newline does not start another line), and then returns exactly the line parser's
//     values; with n + 1 it throws ParseError;
//   * save_parameters -> load_parameters reproduces the values bit for bit.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "fuzz_support.hpp"
#include "sbptt/nn/parameters_io.hpp"

namespace {

using sbptt_fuzz::expect;

/// Splits like std::getline over the whole input: on '\n', with no empty last line after a
/// final '\n'.
std::vector<std::string_view> getline_lines(std::string_view text) {
  std::vector<std::string_view> lines;
  std::size_t start = 0;
  while (start < text.size()) {
    std::size_t end = text.find('\n', start);
    if (end == std::string_view::npos) end = text.size();
    lines.push_back(text.substr(start, end - start));
    start = end + 1;
  }
  return lines;
}

template <class Scalar>
void check(std::string_view text, const std::vector<std::string_view>& lines,
           const sbptt_fuzz::ScratchDir& scratch) {
  // 1. Line by line.
  std::vector<Scalar> values;
  bool all_accepted = true;
  for (const std::string_view line : lines) {
    // The format's line bound (docs/formats.md): longer than any shortest number text, refused
    // by the file reader before the line is parsed, even when it holds a valid number.
    if (line.size() > sbptt::detail::max_number_chars) {
      all_accepted = false;
      continue;
    }
    try {
      const Scalar value = sbptt::detail::parse_finite<Scalar>(line, "fuzz line");
      expect(std::isfinite(value), "parse_finite returned a non-finite value");
      const Scalar reference = sbptt_fuzz::reference_value<Scalar>(line);
      expect(sbptt_fuzz::same_bits(&value, &reference, 1),
             "parse_finite disagrees with strtod/strtof on an accepted line");
      values.push_back(value);
    } catch (const sbptt::ParseError&) {
      all_accepted = false;
    }
  }

  if (!text.empty() && text.back() != '\n') all_accepted = false;

  // 2. The file function on the same bytes.
  const auto input_file = scratch.file("input.txt");
  sbptt_fuzz::write_bytes(input_file, text);
  const auto count = static_cast<sbptt::Index>(lines.size());
  bool loaded = false;
  sbptt::Vector<Scalar> theta;
  try {
    theta = sbptt::load_parameters<Scalar>(input_file, count);
    loaded = true;
  } catch (const sbptt::ParseError&) {
  }
  expect(loaded == all_accepted,
         "load_parameters and the line parser disagree on whether the file is valid");
  if (!loaded) return;
  expect(theta.size() == count, "load_parameters returned the wrong number of values");
  expect(sbptt_fuzz::same_bits(theta.data(), values.data(), values.size()),
         "load_parameters and the line parser disagree on the values");
  for (sbptt::Index i = 0; i < theta.size(); ++i)
    expect(std::isfinite(theta(i)), "load_parameters returned a non-finite value");

  // A wrong count is refused.
  bool refused = false;
  try {
    (void)sbptt::load_parameters<Scalar>(input_file, count + 1);
  } catch (const sbptt::ParseError&) {
    refused = true;
  }
  expect(refused, "load_parameters accepted a file with one number too few");

  // 3. Round trip through the writer.
  const auto saved_file = scratch.file("saved.txt");
  sbptt::save_parameters<Scalar>(saved_file, theta);
  const sbptt::Vector<Scalar> again = sbptt::load_parameters<Scalar>(saved_file, count);
  expect(again.size() == theta.size(), "round trip changed the number of values");
  expect(sbptt_fuzz::same_bits(again.data(), theta.data(), static_cast<std::size_t>(count)),
         "save_parameters -> load_parameters is not bit-identical");
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const sbptt_fuzz::ScratchDir scratch;
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  const std::vector<std::string_view> lines = getline_lines(text);
  check<double>(text, lines, scratch);
  check<float>(text, lines, scratch);
  return 0;
}
