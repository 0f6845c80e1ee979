// Adam on a rotational update field, and what the sign combination does about it
// (paper.md §3.2, the repository's "Adam with Rotation" figure).
//
// Loss L = θ1² + θ2², start (2, 4), 200 Adam iterations, three update fields:
//   plain     v = θ                        (∇(L/2); Adam is invariant to a positive scale of
//                                           its input up to ε, so 2θ gives the same path)
//   rotated   v = θ + k·(−θ2, θ1)          (the same field plus a curl of strength k, the
//                                           stand-in for a modified backward pass)
//   combined  v = combine(rotated, plain)  (rotated plays g_M, the true gradient plays g_R)
//
// Usage: rotation [--k K] [--lr LR] [--iterations N] [--csv FILE]
// Prints the loss of each method at a few iterations and at the end; --csv writes the
// trajectories (iteration, method, theta1, theta2, loss; iteration 0 is the start).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <variant>
#include <vector>

#include "sbptt/optim/adam.hpp"
#include "sbptt/optim/combined_update.hpp"

namespace {

using Vec = sbptt::Vector<double>;

struct Settings {
  double k = 2.0;
  double lr = 0.1;
  long iterations = 200;
  std::string csv;
};

struct Point {
  long iteration;
  double theta1, theta2, loss;
};

double loss(const Vec& theta) { return theta.squaredNorm(); }

Vec plain_field(const Vec& theta) { return theta; }

Vec rotated_field(const Vec& theta, double k) {
  Vec v(2);
  v << theta(0) - k * theta(1), theta(1) + k * theta(0);
  return v;
}

Vec start() {
  Vec theta(2);
  theta << 2.0, 4.0;
  return theta;
}

void record(std::vector<Point>& path, long iteration, const Vec& theta) {
  path.push_back({iteration, theta(0), theta(1), loss(theta)});
}

std::vector<Point> run_plain(const Settings& s, bool rotated) {
  sbptt::Adam<double> adam({.learning_rate = s.lr});
  Vec theta = start();
  std::vector<Point> path;
  record(path, 0, theta);
  for (long it = 1; it <= s.iterations; ++it) {
    adam.step(theta, rotated ? rotated_field(theta, s.k) : plain_field(theta));
    record(path, it, theta);
  }
  return path;
}

std::vector<Point> run_combined(const Settings& s) {
  sbptt::CombinedUpdate<sbptt::Adam<double>> update(sbptt::Adam<double>({.learning_rate = s.lr}));
  Vec theta = start();
  std::vector<Point> path;
  record(path, 0, theta);
  for (long it = 1; it <= s.iterations; ++it) {
    update.step(theta, rotated_field(theta, s.k), plain_field(theta));
    record(path, it, theta);
  }
  return path;
}

std::optional<double> parse_number(std::string_view text) {
  const std::string owned(text);
  char* end = nullptr;
  const double value = std::strtod(owned.c_str(), &end);
  if (owned.empty() || end != owned.c_str() + owned.size() || !std::isfinite(value)) {
    return std::nullopt;
  }
  return value;
}

std::optional<long> parse_count(std::string_view text) {
  const std::string owned(text);
  char* end = nullptr;
  const long value = std::strtol(owned.c_str(), &end, 10);
  if (owned.empty() || end != owned.c_str() + owned.size() || value < 1 || value > 1000000) {
    return std::nullopt;
  }
  return value;
}

void usage(std::ostream& out) {
  out << "usage: rotation [--k K] [--lr LR] [--iterations N] [--csv FILE]\n"
         "  --k K           rotation strength, finite (default 2)\n"
         "  --lr LR         Adam learning rate, finite and > 0 (default 0.1)\n"
         "  --iterations N  Adam steps per method, integer in [1, 1e6] (default 200)\n"
         "  --csv FILE      write iteration,method,theta1,theta2,loss rows to FILE\n";
}

// Returns the settings, or an exit code: 0 after --help, 2 after a bad argument.
std::variant<Settings, int> parse_arguments(int argc, char** argv) {
  Settings s;
  for (int i = 1; i < argc; ++i) {
    std::string_view arg = argv[i];
    if (arg == "--help" || arg == "-h") {
      usage(std::cout);
      return 0;
    }
    std::string_view value;
    std::string_view flag = arg;
    if (const auto eq = arg.find('='); arg.starts_with("--") && eq != std::string_view::npos) {
      flag = arg.substr(0, eq);
      value = arg.substr(eq + 1);
    } else if (flag == "--k" || flag == "--lr" || flag == "--iterations" || flag == "--csv") {
      if (i + 1 >= argc) {
        std::cerr << "rotation: " << flag << " needs a value\n";
        usage(std::cerr);
        return 2;
      }
      value = argv[++i];
    }
    auto bad = [&](const char* expected) {
      std::cerr << "rotation: " << flag << " = \"" << value << "\" is not valid; expected "
                << expected << "\n";
      return 2;
    };
    if (flag == "--k") {
      const auto k = parse_number(value);
      if (!k) return bad("a finite number");
      s.k = *k;
    } else if (flag == "--lr") {
      const auto lr = parse_number(value);
      if (!lr || *lr <= 0) return bad("a finite number > 0");
      s.lr = *lr;
    } else if (flag == "--iterations") {
      const auto n = parse_count(value);
      if (!n) return bad("an integer in [1, 1000000]");
      s.iterations = *n;
    } else if (flag == "--csv") {
      if (value.empty()) return bad("a file name");
      s.csv = std::string(value);
    } else {
      std::cerr << "rotation: unknown argument \"" << arg << "\"\n";
      usage(std::cerr);
      return 2;
    }
  }
  return s;
}

using Runs = std::vector<std::pair<const char*, const std::vector<Point>*>>;

// Written to FILE.tmp and renamed, so a failed run leaves no half-written FILE behind.
bool write_csv(const std::string& file, const Runs& runs) {
  const std::string tmp = file + ".tmp";
  {
    std::ofstream out(tmp);
    if (!out) {
      std::cerr << "rotation: cannot open \"" << tmp << "\" for writing\n";
      return false;
    }
    out << "iteration,method,theta1,theta2,loss\n";
    char line[160];
    for (const auto& [name, path] : runs) {
      for (const Point& p : *path) {
        std::snprintf(line, sizeof line, "%ld,%s,%.17g,%.17g,%.17g\n", p.iteration, name,
                      p.theta1, p.theta2, p.loss);
        out << line;
      }
    }
    out.flush();
    if (!out) {
      std::cerr << "rotation: writing \"" << tmp << "\" failed\n";
      std::filesystem::remove(tmp);
      return false;
    }
  }
  std::error_code ec;
  std::filesystem::rename(tmp, file, ec);
  if (ec) {
    std::cerr << "rotation: cannot rename \"" << tmp << "\" to \"" << file << "\": "
              << ec.message() << "\n";
    std::filesystem::remove(tmp, ec);
    return false;
  }
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    const auto parsed = parse_arguments(argc, argv);
    if (const int* code = std::get_if<int>(&parsed)) return *code;
    const Settings s = std::get<Settings>(parsed);

    const auto plain = run_plain(s, false);
    const auto rotated = run_plain(s, true);
    const auto combined = run_combined(s);
    const Runs runs = {
        {"plain", &plain}, {"rotated", &rotated}, {"combined", &combined}};

    std::printf("Adam on L = theta1^2 + theta2^2 from (2, 4): k = %g, lr = %g, %ld iterations\n",
                s.k, s.lr, s.iterations);
    std::printf("%-10s", "iteration");
    for (const auto& [name, path] : runs) std::printf("%14s", name);
    std::printf("\n");
    std::vector<long> rows;
    for (long it : {0L, 20L, 40L, 60L, 80L, 100L, 150L}) {
      if (it < s.iterations) rows.push_back(it);
    }
    rows.push_back(s.iterations);
    for (long it : rows) {
      std::printf("%-10ld", it);
      for (const auto& [name, path] : runs) {
        std::printf("%14.4g", (*path)[static_cast<std::size_t>(it)].loss);
      }
      std::printf("\n");
    }
    for (const auto& [name, path] : runs) {
      long first = -1;
      double low = path->front().loss, high = 0.0;
      for (const Point& p : *path) {
        if (first < 0 && p.loss < 1e-2) first = p.iteration;
      }
      // Range over the second half, to tell a plateau or orbit from steady convergence.
      for (std::size_t i = path->size() / 2; i < path->size(); ++i) {
        low = std::min(low, (*path)[i].loss);
        high = std::max(high, (*path)[i].loss);
      }
      const std::string reached =
          first < 0 ? "never below 1e-2" : "first below 1e-2 at " + std::to_string(first);
      std::printf("%-9s final loss %.4g; %s; second-half range [%.3g, %.3g]\n", name,
                  path->back().loss, reached.c_str(), low, high);
    }
    if (!s.csv.empty()) {
      if (!write_csv(s.csv, runs)) return 1;
      std::printf("trajectories written to %s\n", s.csv.c_str());
    }
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "rotation: " << e.what() << "\n";
    return 1;
  }
}
