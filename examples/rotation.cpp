// Adam on a rotational update field, and what the sign combination does about it
// (docs/paper.md §3.2, the repository's "Adam with Rotation" figure).
//
// Loss L = θ1² + θ2², start (2, 4), 200 Adam iterations, three update fields:
//   plain     v = θ                        (∇(L/2); Adam is invariant to a positive scale of
//                                           its input up to ε, so 2θ gives the same path)
//   rotated   v = θ + k·(−θ2, θ1)          (the same field plus a curl of strength k, the
//                                           stand-in for a modified backward pass)
//   combined  v = combine(rotated, plain)  (rotated plays g_M, the true gradient plays g_R)
//
// Usage: rotation [--k K] [--lr LR] [--iterations N] [--csv FILE]
// Prints the loss of each method at a few iterations and at the end, and writes the
// trajectories (iteration, method, theta1, theta2, loss; iteration 0 is the start) to
// rotation.csv, or to the --csv FILE.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <iostream>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "sbptt/optim/adam.hpp"
#include "sbptt/optim/combined_update.hpp"
#include "sbptt/core/atomic_file.hpp"

#include "command_line.hpp"
#include "standard_streams.hpp"

namespace {

using Vec = sbptt::Vector<double>;

struct Settings {
  double k = 2.0;
  double lr = 0.1;
  long iterations = 200;
  std::string csv = "rotation.csv";
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

// Returns false after --help; throws sbptt::InvalidArgument naming the flag and what was
// expected.
bool parse_arguments(int argc, const char* const* argv, Settings& s) {
  sbptt::examples::CommandLine cli(
      "rotation", "Adam on a rotational update field and what the combined update does about "
                  "it (docs/rotation.md). Exit codes: 0 success, 1 error, 2 bad flag.");
  cli.number("--k", s.k, -1e6, 1e6, "rotation strength of the curl added to the gradient");
  cli.number("--lr", s.lr, 1e-300, 1e6, "Adam learning rate");
  cli.integer("--iterations", s.iterations, 1, 1000000, "Adam steps per method");
  cli.path("--csv", s.csv, "write the iteration,method,theta1,theta2,loss rows here", s.csv);
  return cli.parse(argc, argv);
}

using Runs = std::vector<std::pair<const char*, const std::vector<Point>*>>;

std::string csv_text(const Runs& runs) {
  std::string text = "iteration,method,theta1,theta2,loss\n";
  char line[160];
  for (const auto& [name, path] : runs) {
    for (const Point& p : *path) {
      std::snprintf(line, sizeof line, "%ld,%s,%.17g,%.17g,%.17g\n", p.iteration, name,
                    p.theta1, p.theta2, p.loss);
      text += line;
    }
  }
  return text;
}

}  // namespace

int main(int argc, char** argv) {
  Settings s;
  try {
    if (!parse_arguments(argc, argv, s))
      return sbptt::examples::with_streams_checked("rotation", 0);
  } catch (const sbptt::InvalidArgument& e) {
    std::cerr << "rotation: " << e.what() << "\n";
    return 2;
  }
  try {
    sbptt::check_output_path(s.csv, "--csv");

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
    sbptt::write_file_atomically(s.csv, csv_text(runs));
    std::printf("trajectories written to %s\n", s.csv.c_str());
    return sbptt::examples::with_streams_checked("rotation", 0);
  } catch (const std::exception& e) {
    std::cerr << "rotation: " << e.what() << "\n";
    return 1;
  }
}
