#pragma once
// Runs the example programs as a user does (through the shell), for the tests of
// tests/programs/.
#include <catch2/catch.hpp>

#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>
#include <string>
#include <vector>

namespace sbptt::testing {

struct Result {
  int status = -1;
  std::string output;  // stdout and stderr
};

/// Runs `program` through the shell; `shell_prefix` (e.g. a ulimit) goes before it.
inline Result run(const std::string& program, const std::string& arguments,
           const std::string& shell_prefix = "") {
  // SBPTT_EXAMPLES_DIR (environment) runs the tests against other builds of the programs (e.g.
  // those from before a fix), as in test_program_outputs.cpp.
  const char* override_dir = std::getenv("SBPTT_EXAMPLES_DIR");
  const std::string command = shell_prefix + (override_dir ? override_dir : SBPTT_EXAMPLES_DIR) +
                              "/" + program + " " + arguments + " 2>&1";
  Result result;
  FILE* pipe = popen(command.c_str(), "r");
  REQUIRE(pipe != nullptr);
  char buffer[4096];
  while (std::fgets(buffer, sizeof buffer, pipe)) result.output += buffer;
  const int status = pclose(pipe);
  result.status = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return result;
}

inline std::filesystem::path scratch(const std::string& name) {
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("sbptt_programs_" + std::to_string(getpid()));
  std::filesystem::create_directories(dir);
  return dir / name;
}

inline std::string file_text(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), {}};
}

/// The value of `loss=<value>` that --dump-gradients prints.
inline double printed_loss(const std::string& output) {
  const auto at = output.find("loss=");
  REQUIRE(at != std::string::npos);
  return std::stod(output.substr(at + 5));
}

/// Column `column` (1 = R) of a --dump-gradients CSV, one entry per parameter.
inline std::vector<double> gradient_column(const std::filesystem::path& csv, int column) {
  std::ifstream in(csv);
  std::string line;
  std::getline(in, line);
  REQUIRE(line == "param,R,M,C,S,N");
  std::vector<double> values;
  while (std::getline(in, line)) {
    std::stringstream fields(line);
    std::string field;
    for (int i = 0; i <= column; ++i) std::getline(fields, field, ',');
    values.push_back(std::stod(field));
  }
  return values;
}

}  // namespace sbptt::testing
