// The states file (docs/formats.md): exact round trips and a clear error for every malformed input.
#include <catch2/catch.hpp>

#include <filesystem>
#include <fstream>
#include <cmath>
#include <cstring>
#include <limits>

#include "sbptt/core/rng.hpp"
#include "sbptt/train/states_io.hpp"
#include "support/files.hpp"

using namespace sbptt;
using Catch::Contains;

TEST_CASE("states file: save then load reproduces every bit", "[io]") {
  Rng rng(3);
  Matrix<double> states(5, 7);
  for (Index i = 0; i < states.size(); ++i) states(i) = rng.normal() * std::pow(10.0, rng.uniform(-300, 300));
  states(0, 0) = -0.0;
  states(1, 0) = std::numeric_limits<double>::denorm_min();
  const auto path = std::filesystem::temp_directory_path() / "sbptt_states_roundtrip.csv";
  save_states(path, states);
  const Matrix<double> loaded = load_states<double>(path, 5);
  REQUIRE(loaded.rows() == 5);
  REQUIRE(loaded.cols() == 7);
  for (Index i = 0; i < states.size(); ++i)
    CHECK(std::memcmp(&loaded(i), &states(i), sizeof(double)) == 0);
}

TEST_CASE("states file: one row per sample in the state layout", "[io]") {
  const Matrix<double> m = parse_states<double>("1,2,3\n4, 5 ,6\r\n\n", 3, "inline");
  CHECK(m.cols() == 2);
  CHECK(m(0, 1) == 4.0);
  CHECK(m(1, 1) == 5.0);
  CHECK(m(2, 0) == 3.0);
}

TEST_CASE("states file: every malformed input names its line and what was expected", "[io]") {
  auto parse = [](const char* text) { return parse_states<double>(text, 3, "s.csv"); };
  REQUIRE_THROWS_AS(parse(""), ParseError);
  REQUIRE_THROWS_WITH(parse(""), Contains("holds no samples") && Contains("3 numbers"));
  REQUIRE_THROWS_WITH(parse("\n  \n"), Contains("holds no samples"));
  REQUIRE_THROWS_WITH(parse("1,2,3\n1,2\n"), Contains("line 2") && Contains("2 columns; expected exactly state_dim = 3"));
  REQUIRE_THROWS_WITH(parse("1,2,3,4\n"), Contains("line 1") && Contains("more than 3 columns"));
  REQUIRE_THROWS_WITH(parse("1,x,3\n"), Contains("line 1, column 2") && Contains("'x' is not a number"));
  REQUIRE_THROWS_WITH(parse("1,nan,3\n"), Contains("column 2") && Contains("not finite"));
  REQUIRE_THROWS_WITH(parse("1,2,inf\n"), Contains("column 3") && Contains("not finite"));
  REQUIRE_THROWS_WITH(parse("1,2,3abc\n"), Contains("trailing characters 'abc'"));
  REQUIRE_THROWS_WITH(parse("1,,3\n"), Contains("column 2") && Contains("empty"));
  REQUIRE_THROWS_WITH(parse("1,2,1e999\n"), Contains("out of range"));
}

TEST_CASE("states file: a last row with no newline after it is refused as cut", "[io]") {
  // save_states ends every row with a newline; a copy cut inside its last number would
  // otherwise load a different state for that sample.
  const auto path = std::filesystem::temp_directory_path() / "sbptt_states_cut.csv";
  std::ofstream(path, std::ios::binary) << "1,2,3\n4,5,0.25";
  REQUIRE_THROWS_AS(load_states<double>(path, 3), ParseError);
  REQUIRE_THROWS_WITH(load_states<double>(path, 3),
                      Contains("sbptt_states_cut.csv', line 2") && Contains("'4,5,0.25'") &&
                          Contains("no newline") && Contains("cut short"));
  std::ofstream(path, std::ios::binary) << "1,2,3\n4,5,0.25\n\t";
  CHECK(load_states<double>(path, 3)(2, 1) == 0.25);
  std::filesystem::remove(path);
}

TEST_CASE("states file: unreadable paths are IoErrors naming the path", "[io]") {
  REQUIRE_THROWS_AS(load_states<double>("/nonexistent/states.csv", 2), IoError);
  // A read that fails after the open (EIO from /proc/self/mem at offset 0).
  REQUIRE_THROWS_AS(load_states<double>("/proc/self/mem", 2), IoError);
  REQUIRE_THROWS_WITH(load_states<double>("/proc/self/mem", 2),
                      Catch::Contains("reading states file '/proc/self/mem' failed"));
  REQUIRE_THROWS_WITH(load_states<double>("/nonexistent/states.csv", 2), Contains("/nonexistent/states.csv"));
  REQUIRE_THROWS_WITH(load_states<double>(std::filesystem::temp_directory_path(), 2), Contains("is a directory"));
  REQUIRE_THROWS_AS(save_states<double>("/nonexistent/dir/s.csv", Matrix<double>::Zero(2, 2)), IoError);
}

TEST_CASE("states file: reading is bounded by the longest row state_dim numbers can make", "[io]") {
  const auto path = std::filesystem::temp_directory_path() / "sbptt_states_long.csv";
  // 4 MB without a newline: refused after 3 × 65 characters.
  std::ofstream(path, std::ios::binary) << std::string(4'000'000, '0');
  REQUIRE_THROWS_WITH(load_states<double>(path, 3),
                      Contains("line 1: longer than 195 characters") &&
                          Contains("expected a row of 3 numbers"));
  std::ofstream(path, std::ios::binary) << "1,2,3\n\n";  // a trailing blank line is fine
  CHECK(load_states<double>(path, 3).cols() == 1);
  std::filesystem::remove(path);
}

TEST_CASE("states file: a file that cannot be opened says why", "[io]") {
  REQUIRE_THROWS_WITH(load_states<double>("/nonexistent/states.csv", 2),
                      Contains("(No such file or directory)"));
}

TEST_CASE("states file: read from a pipe as from a file (docs/formats.md)", "[io]") {
  const testing::PipeHolding pipe("1,-2.5\n0.125,3e-3\n4,5\n");
  const Matrix<double> states = load_states<double>(pipe.path(), 2);
  REQUIRE(states.rows() == 2);
  REQUIRE(states.cols() == 3);
  CHECK(states(0, 0) == 1.0);
  CHECK(states(1, 0) == -2.5);
  CHECK(states(0, 1) == 0.125);
  CHECK(states(1, 1) == 3e-3);
  CHECK(states(0, 2) == 4.0);
  CHECK(states(1, 2) == 5.0);
}
