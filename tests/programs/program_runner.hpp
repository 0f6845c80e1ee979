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
#include <sstream>
#include <string>
#include <vector>

#include "support/files.hpp"

namespace sbptt::testing {

/// The programs' directory of this build, or SBPTT_EXAMPLES_DIR from the environment: the
/// tests then run against other builds of the programs (e.g. those from before a fix).
inline std::string examples_dir() {
  const char* override_dir = std::getenv("SBPTT_EXAMPLES_DIR");
  return override_dir != nullptr ? override_dir : SBPTT_EXAMPLES_DIR;
}

struct Result {
  int status = -1;
  std::string output;  // what reaches the pipe: stdout and stderr unless redirected
};

/// Runs `program` through the shell; `shell_prefix` (e.g. a ulimit) goes before it and
/// `redirections` after it: by default both streams are read.
inline Result run(const std::string& program, const std::string& arguments,
                  const std::string& shell_prefix = "",
                  const std::string& redirections = "2>&1") {
  const std::string command =
      shell_prefix + examples_dir() + "/" + program + " " + arguments + " " + redirections;
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
