// A user-defined scene trained with the combined update: a point mass on a line with friction,
// pushed by a force u, must stop at the origin (final-state loss). The scene (point_mass.hpp)
// is its equations, written once as a step templated on the scalar; AutoDiffSimulator derives
// its Jacobians.
#include <csignal>
#include <cstdio>
#include <cstring>

#include "point_mass.hpp"

namespace {

/// `code`, or 1 in place of 0 if stdout could not take what was printed: the losses (or the
/// usage) are the program's result.
int with_stdout_checked(int code) {
  if (code != 0 || (std::fflush(stdout) == 0 && std::ferror(stdout) == 0)) return code;
  std::fprintf(stderr, "custom_simulator: standard output was not written in full\n");
  return 1;
}

}  // namespace

int main(int argc, char** argv) {
  // Past `ulimit -f`, or with the reader of stdout gone (`| head`), a write then fails
  // instead of killing the program unreported.
  std::signal(SIGXFSZ, SIG_IGN);
  std::signal(SIGPIPE, SIG_IGN);
  if (argc == 2 && std::strcmp(argv[1], "--help") == 0) {
    std::printf("usage: custom_simulator\ntrains the point mass of docs/api.md with the combined "
                "update, printing its loss every 200 iterations up to 1000; no options\n");
    return with_stdout_checked(0);
  }
  if (argc > 1) {
    const char* unexpected = std::strcmp(argv[1], "--help") == 0 ? argv[2] : argv[1];
    std::fprintf(stderr, "custom_simulator takes no arguments but --help alone (it trains the "
                         "point mass of docs/api.md); got '%s'\n", unexpected);
    return 2;
  }
  using Loss = sbptt::SquaredDistanceLoss<PointMass::State>;
  const PointMass sim;
  auto network = sbptt::Network<double>::mlp(2, {32, 32}, 1);
  sbptt::Rng rng(1);
  sbptt::glorot_uniform(network, rng, {.zero_last_kernel = true});
  sbptt::Matrix<double> starts(2, 64);
  for (sbptt::Index i = 0; i < starts.size(); ++i) starts(i) = rng.uniform(-1, 1);

  sbptt::Engine engine(sim, network, sbptt::Objective<Loss>{Loss{PointMass::State::Zero()}}, 30);
  sbptt::CombinedUpdate<sbptt::Adam<double>> update(sbptt::Adam<double>({.learning_rate = 3e-3}));
  for (int iteration = 0; iteration <= 1000; ++iteration) {
    const auto pair = engine.regular_and_modified(starts);  // one forward pass, two sweeps
    if (iteration % 200 == 0)
      std::printf("iteration %4d  loss %.3e  cos(g_M, g_R) %+.3f  signs agree %.2f\n", iteration,
                  pair.loss, pair.comparison.cos_modified_regular, pair.comparison.agree_fraction);
    update.step(network.params(), pair.modified, pair.regular);
  }
  return with_stdout_checked(0);
}
