// The parameters file (docs/formats.md): exact round trips, printf-identical text, and every kind of
// malformed file refused with the file, line and text named.
#include <catch2/catch.hpp>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>
#include <string>

#include <unistd.h>

#include "sbptt/nn/init.hpp"
#include "sbptt/nn/parameters_io.hpp"
#include "support/files.hpp"

namespace fs = std::filesystem;
using Catch::Contains;
using sbptt::Index;
using sbptt::Network;

namespace {

// A fresh directory per test case, removed at the end.
struct TempDir {
  fs::path path;
  TempDir() {
    static int counter = 0;
    path = fs::temp_directory_path() /
           ("sbptt_nn_io_" + std::to_string(::getpid()) + "_" + std::to_string(++counter));
    fs::remove_all(path);
    fs::create_directories(path);
  }
  ~TempDir() {
    std::error_code ignored;
    fs::remove_all(path, ignored);
  }
};

void write_text(const fs::path& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary);
  out << text;
}

std::string read_text(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream buffer;
  buffer << in.rdbuf();
  return buffer.str();
}

template <class Scalar>
bool bitwise_equal(const sbptt::Vector<Scalar>& a, const sbptt::Vector<Scalar>& b) {
  return a.size() == b.size() &&
         std::memcmp(a.data(), b.data(), sizeof(Scalar) * static_cast<std::size_t>(a.size())) == 0;
}

}  // namespace

TEMPLATE_TEST_CASE("parameters round-trip bit for bit", "[nn][io]", float, double) {
  using S = TestType;
  TempDir dir;
  auto net = Network<S>::mlp(24, {100, 100}, 4);
  sbptt::Rng rng(42);
  sbptt::glorot_uniform(net, rng);
  // Values that need every digit, and the extremes of the format.
  using limits = std::numeric_limits<S>;
  const S specials[] = {S(0.1), S(1) / S(3), S(-0.0), limits::max(), limits::lowest(),
                        limits::min(), limits::denorm_min(), limits::epsilon(), S(1e-30)};
  for (Index i = 0; i < 9; ++i) net.params()(i) = specials[i];

  const fs::path file = dir.path / "theta.txt";
  sbptt::save_parameters(file, net);
  auto copy = Network<S>::mlp(24, {100, 100}, 4);
  sbptt::load_parameters(file, copy);
  CHECK(bitwise_equal<S>(copy.params(), net.params()));
  CHECK(std::signbit(copy.params()(2)));

  // Nothing else is left in the directory (the temporary was renamed).
  Index entries = 0;
  for ([[maybe_unused]] const auto& entry : fs::directory_iterator(dir.path)) ++entries;
  CHECK(entries == 1);

  // Overwriting an existing file works and replaces its contents.
  net.params().setConstant(S(2));
  sbptt::save_parameters(file, net);
  sbptt::load_parameters(file, copy);
  CHECK(copy.params() == net.params());
}

TEMPLATE_TEST_CASE("the text is printf %.17g (double) / %.9g (float), one per line", "[nn][io]",
                   float, double) {
  using S = TestType;
  TempDir dir;
  sbptt::Vector<S> theta(5);
  theta << S(0.1), S(-2.5e-8), S(123456789.0), S(0), S(1) / S(3);
  const fs::path file = dir.path / "theta.txt";
  sbptt::save_parameters(file, theta);
  const char* format = std::is_same_v<S, float> ? "%.9g\n" : "%.17g\n";
  std::string expected;
  for (Index i = 0; i < theta.size(); ++i) {
    char line[64];
    std::snprintf(line, sizeof line, format, static_cast<double>(theta(i)));
    expected += line;
  }
  CHECK(read_text(file) == expected);
  const auto loaded = sbptt::load_parameters<S>(file, 5);
  CHECK(loaded == theta);
}

TEST_CASE("loading accepts blanks and CRLF, and numbers from other writers", "[nn][io]") {
  TempDir dir;
  const fs::path file = dir.path / "theta.txt";
  write_text(file, "  1.5\t\r\n+2\n-3e-2 \n4.\n.5\n1E+2\n");
  const auto theta = sbptt::load_parameters<double>(file, 6);
  CHECK(theta(0) == 1.5);
  CHECK(theta(1) == 2.0);
  CHECK(theta(2) == -0.03);
  CHECK(theta(3) == 4.0);
  CHECK(theta(4) == 0.5);
  CHECK(theta(5) == 100.0);
}

TEST_CASE("malformed parameters files are refused with the line and the text", "[nn][io]") {
  TempDir dir;
  const fs::path file = dir.path / "bad.txt";
  const auto load = [&](const std::string& text, Index expected) {
    write_text(file, text);
    return sbptt::load_parameters<double>(file, expected);
  };
  REQUIRE_THROWS_AS(load("1\n2\nabc\n4\n", 4), sbptt::ParseError);
  REQUIRE_THROWS_WITH(load("1\n2\nabc\n4\n", 4),
                      Contains("line 3") && Contains("'abc' is not a number") &&
                          Contains("bad.txt"));
  REQUIRE_THROWS_WITH(load("1\nnan\n", 2), Contains("line 2") && Contains("'nan' is not finite"));
  REQUIRE_THROWS_WITH(load("1\n2\n-inf\n", 3), Contains("line 3") && Contains("'-inf'"));
  REQUIRE_THROWS_WITH(load("1\n2\n3\n1e999\n", 4), Contains("line 4") && Contains("1e999"));
  REQUIRE_THROWS_WITH(load("1.5x\n", 1), Contains("line 1") && Contains("trailing characters 'x'"));
  REQUIRE_THROWS_WITH(load("1\n2.0 3.0\n", 2), Contains("line 2") && Contains("' 3.0'"));
  REQUIRE_THROWS_WITH(load("1\n\n3\n", 3), Contains("line 2") && Contains("empty, expected one number"));
  REQUIRE_THROWS_WITH(load("1,5\n", 1), Contains("line 1") && Contains("trailing characters ',5'"));
  REQUIRE_THROWS_WITH(load("++1\n", 1), Contains("line 1") && Contains("'++1'"));
  REQUIRE_THROWS_WITH(load("1\n2\n3\n", 4), Contains("expected 4 numbers, got 3"));
  // One number too many is refused at that line, before the rest of the file is read.
  REQUIRE_THROWS_WITH(load("1\n2\n3\n4\n5\nnot read\n", 4),
                      Contains("line 5: more than the 4 numbers expected"));
  REQUIRE_THROWS_WITH(load("", 4), Contains("expected 4 numbers, got 0"));
  REQUIRE_NOTHROW(load("1\n2\n3\n4\n", 4));
}

TEST_CASE("reading a parameters file is bounded and never echoes binary bytes", "[nn][io]") {
  TempDir dir;
  const fs::path file = dir.path / "long.txt";
  // 4 MB of digits and no newline (like /dev/zero): refused after 64 characters, by line 1.
  write_text(file, std::string(4'000'000, '1'));
  REQUIRE_THROWS_WITH(sbptt::load_parameters<double>(file, 2),
                      Contains("line 1: longer than 64 characters") &&
                          Contains("expected one number per line"));
  // A number needs at most 25 characters; 64 leaves room for blanks, and no more.
  write_text(file, std::string(64, ' ') + "1\n2\n");
  REQUIRE_THROWS_WITH(sbptt::load_parameters<double>(file, 2), Contains("line 1: longer than 64"));
  write_text(file, std::string(63, ' ') + "1\n2\n");
  CHECK(sbptt::load_parameters<double>(file, 2)(0) == 1.0);
  // Bytes of a binary file are shown escaped, never raw.
  write_text(file, std::string("\x01\x7f\xff\x1b[2J", 7) + "\n");
  try {
    (void)sbptt::load_parameters<double>(file, 1);
    FAIL("a binary line was accepted");
  } catch (const sbptt::ParseError& e) {
    const std::string message = e.what();
    CHECK(message.find("'\\x01\\x7f\\xff\\x1b[2J' is not a number") != std::string::npos);
    CHECK(message.find('\x1b') == std::string::npos);
  }
}

TEST_CASE("a trailing blank line is accepted in parameters files, as in states files",
          "[nn][io]") {
  TempDir dir;
  const fs::path file = dir.path / "trailing.txt";
  write_text(file, "1.5\n-2\n\n  \n");
  const auto theta = sbptt::load_parameters<double>(file, 2);
  CHECK(theta(0) == 1.5);
  CHECK(theta(1) == -2.0);
  // In the middle a blank line still means a missing number.
  write_text(file, "1.5\n\n-2\n");
  REQUIRE_THROWS_WITH(sbptt::load_parameters<double>(file, 2), Contains("line 2: empty"));
}

TEST_CASE("a parameters file whose last number has no newline after it is refused as cut",
          "[nn][io]") {
  // save_parameters ends every line with a newline. A copy cut inside its last number
  // ("0.123456789" → "0.1234") would otherwise load as a different controller.
  TempDir dir;
  const fs::path file = dir.path / "cut.txt";
  write_text(file, "1.5\n-2\n0.1234");
  REQUIRE_THROWS_AS(sbptt::load_parameters<double>(file, 3), sbptt::ParseError);
  REQUIRE_THROWS_WITH(sbptt::load_parameters<double>(file, 3),
                      Contains("cut.txt', line 3") && Contains("'0.1234'") &&
                          Contains("no newline") && Contains("cut short"));
  // A last line that is wrong anyway is named for what is wrong with it.
  write_text(file, "1.5\n-2\nabc");
  REQUIRE_THROWS_WITH(sbptt::load_parameters<double>(file, 3), Contains("'abc' is not a number"));
  // Blanks after the last newline lose nothing: accepted, as trailing blank lines are.
  write_text(file, "1.5\n-2\n0.1234\n  ");
  CHECK(sbptt::load_parameters<double>(file, 3)(2) == 0.1234);
}

TEST_CASE("a parameters file that cannot be opened says why", "[nn][io]") {
  REQUIRE_THROWS_WITH(sbptt::load_parameters<double>("/nonexistent/p.txt", 2),
                      Contains("cannot open '/nonexistent/p.txt' for reading (No such file or "
                               "directory)"));
}

TEST_CASE("parameters are read from a pipe as from a file (docs/formats.md)", "[nn][io]") {
  const sbptt::testing::PipeHolding pipe("0.25\n-1e-3\n7\n");
  const auto theta = sbptt::load_parameters<double>(pipe.path(), 3);
  REQUIRE(theta.size() == 3);
  CHECK(theta(0) == 0.25);
  CHECK(theta(1) == -1e-3);
  CHECK(theta(2) == 7.0);
}

TEST_CASE("a failed load leaves the controller unchanged", "[nn][io]") {
  TempDir dir;
  const fs::path file = dir.path / "short.txt";
  write_text(file, "1\n2\n3\n");
  auto net = Network<double>::mlp(2, {3}, 1);
  net.params().setConstant(7);
  REQUIRE_THROWS_WITH(sbptt::load_parameters(file, net),
                      Contains("expected 13 numbers, got 3"));
  CHECK((net.params().array() == 7).all());
}

TEST_CASE("unreadable and unwritable paths are IoErrors", "[nn][io]") {
  TempDir dir;
  const sbptt::Vector<double> theta = sbptt::Vector<double>::Ones(3);
  REQUIRE_THROWS_AS(sbptt::load_parameters<double>(dir.path / "missing.txt", 3), sbptt::IoError);
  REQUIRE_THROWS_WITH(sbptt::load_parameters<double>(dir.path / "missing.txt", 3),
                      Contains("missing.txt"));
  REQUIRE_THROWS_WITH(sbptt::load_parameters<double>(dir.path, 3), Contains("is a directory"));
  // A read that fails after the open (the kernel refuses reads of /proc/self/mem at offset 0
  // with EIO): libstdc++'s own "basic_filebuf::underflow" exception, not an IoError, escaped.
  REQUIRE_THROWS_AS(sbptt::load_parameters<double>("/proc/self/mem", 3), sbptt::IoError);
  REQUIRE_THROWS_WITH(sbptt::load_parameters<double>("/proc/self/mem", 3),
                      Contains("reading parameters file '/proc/self/mem' failed"));
  REQUIRE_THROWS_AS(sbptt::save_parameters(dir.path / "no_such_dir" / "theta.txt", theta),
                    sbptt::IoError);
  // Renaming a file over a non-empty directory fails: the temporary must not survive.
  fs::create_directories(dir.path / "occupied" / "child");
  REQUIRE_THROWS_AS(sbptt::save_parameters(dir.path / "occupied", theta), sbptt::IoError);
  Index entries = 0;
  for ([[maybe_unused]] const auto& entry : fs::directory_iterator(dir.path)) ++entries;
  CHECK(entries == 1);
}

TEST_CASE("non-finite parameters are not saved", "[nn][io]") {
  TempDir dir;
  sbptt::Vector<double> theta = sbptt::Vector<double>::Ones(4);
  theta(2) = std::numeric_limits<double>::quiet_NaN();
  const fs::path file = dir.path / "theta.txt";
  REQUIRE_THROWS_AS(sbptt::save_parameters(file, theta), sbptt::NonFiniteError);
  REQUIRE_THROWS_WITH(sbptt::save_parameters(file, theta), Contains("parameter 2"));
  CHECK_FALSE(fs::exists(file));
}
