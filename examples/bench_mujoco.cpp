// What MuJoCo costs per time step against an analytic simulator, and how accurate its
// finite-difference Jacobians are: the physical cart pole (1 and 2 poles) as CartPole
// (analytic A, B and an O(P) VJP) and as MJCF through MujocoSimulator (mj_step,
// mjd_transitionFD), plus the double pendulum of examples/models.
//   bench_mujoco [--repeats N] [--source DIR]      exit 0, 1 error, 2 bad flag
//
// Columns (one thread; the best of N timed repeats of a loop over 64 states, so another
// process on the machine inflates them, never deflates):
//   step ns        one step
//   jacobians ns   one A, B
//   vjp ns         one Aᵀλ, Bᵀλ (what the engine calls per sample and step of a sweep)
// Then, for the cart pole, the largest |A_FD − A_analytic| over the 64 states for several
// finite-difference steps ε: truncation O(ε²) against rounding O(1e-16 / ε).
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <exception>
#include <string>
#include <vector>

#include <sbptt/core/finite_difference.hpp>
#include <sbptt/core/instruction_set.hpp>
#include <sbptt/core/rng.hpp>
#include <sbptt/sim/cartpole.hpp>
#include <sbptt/sim/mujoco.hpp>

#include "command_line.hpp"
#include "standard_streams.hpp"
#include "mujoco_cartpole_layout.hpp"

using namespace sbptt;

namespace {

struct Costs {
  double step_ns = 0, jacobians_ns = 0, vjp_ns = 0;
};

/// Best-of-`repeats` time of `body` over all states, in ns per call.
template <class Body>
double best_ns(int repeats, Index calls, Body&& body) {
  double best = 1e300;
  for (int r = 0; r < repeats; ++r) {
    const auto start = std::chrono::steady_clock::now();
    body();
    const std::chrono::duration<double, std::nano> took = std::chrono::steady_clock::now() - start;
    best = std::min(best, took.count() / static_cast<double>(calls));
  }
  return best;
}

template <class Sim>
Costs measure(const Sim& sim, const std::vector<typename Sim::State>& states, int repeats) {
  typename Sim::Control u;
  u.setConstant(sim.control_dim(), 0.5);
  typename Sim::State next, lambda_x, lambda = states.front();
  typename Sim::Control lambda_u;
  typename Sim::StateJacobian a;
  typename Sim::ControlJacobian b;
  const auto n = static_cast<Index>(states.size());
  Costs c;
  double sink = 0;  // keeps the loops from being optimised away
  c.step_ns = best_ns(repeats, n, [&] {
    for (const auto& x : states) {
      sim.step(x, u, next);
      sink += next(0);
    }
  });
  c.jacobians_ns = best_ns(repeats, n, [&] {
    for (const auto& x : states) {
      sim.jacobians(x, u, a, b);
      sink += a(0, 0);
    }
  });
  c.vjp_ns = best_ns(repeats, n, [&] {
    for (const auto& x : states) {
      sim.vjp(x, u, lambda, &lambda_x, &lambda_u);
      sink += lambda_x(0);
    }
  });
  if (sink == 0.123456789) std::printf(" ");
  return c;
}

void print_row(const char* name, const Costs& c, const Costs* reference) {
  std::printf("%-38s %10.0f %12.0f %10.0f", name, c.step_ns, c.jacobians_ns, c.vjp_ns);
  if (reference != nullptr)
    std::printf("   x%.0f  x%.0f  x%.0f", c.step_ns / reference->step_ns,
                c.jacobians_ns / reference->jacobians_ns, c.vjp_ns / reference->vjp_ns);
  std::printf("\n");
}

/// The models of the rows, read from the source tree before any measurement.
struct Models {
  MujocoModelPtr cartpole[2];  ///< physical, 1 and 2 poles
  MujocoModelPtr double_pendulum;
};

/// Throws `IoError` naming --source if a model cannot be read or compiled.
Models read_models(const std::string& source) {
  try {
    Models models;
    for (const int poles : {1, 2})
      models.cartpole[poles - 1] = load_mujoco_model(
          source + "/tests/models/cartpole_physical_" + std::to_string(poles) + ".xml");
    models.double_pendulum = load_mujoco_model(source + "/examples/models/double_pendulum.xml");
    return models;
  } catch (const Error& e) {
    throw IoError(detail::concat("--source '", source, "': ", e.what(), "; expected the sbptt "
                                 "source tree, with tests/models and examples/models"));
  }
}

void cartpole_rows(Index poles, const mjModel& model, int repeats) {
  CartPoleOptions options;
  options.model = CartPoleModel::Physical;
  const CartPole<double, Eigen::Dynamic> cart(poles, options);
  const MujocoSimulator<double> mj(model);
  Rng rng(1);
  const Matrix<double> starts = cartpole_initial_states(cart, rng, 64);
  std::vector<Vector<double>> cart_states, mj_states;
  for (Index j = 0; j < starts.cols(); ++j) {
    cart_states.emplace_back(starts.col(j));
    mj_states.push_back(examples::to_mujoco_layout(starts.col(j), poles));
  }
  const Costs analytic = measure(cart, cart_states, repeats);
  const Costs fd = measure(mj, mj_states, repeats);
  const std::string p = std::to_string(poles);
  print_row(("cart pole " + p + ", CartPole (analytic)").c_str(), analytic, nullptr);
  print_row(("cart pole " + p + ", MuJoCo (mjd_transitionFD)").c_str(), fd, &analytic);

  // Accuracy of the finite differences against the analytic A, per ε.
  std::printf("  max |A_FD - A| over 64 states, cart pole %s:", p.c_str());
  const Matrix<double> pi = examples::mujoco_layout_permutation(poles);
  for (const double eps : {1e-2, 1e-4, 1e-6, 1e-8, 1e-10}) {
    const MujocoSimulator<double> probe(model, MujocoOptions{eps});
    double worst = 0;
    for (std::size_t s = 0; s < cart_states.size(); ++s) {
      Matrix<double> a, a_fd, b_fd;
      Vector<double> b;
      Eigen::Matrix<double, 1, 1> u;
      u(0) = 0.5;
      cart.jacobians(cart_states[s], u, a, b);
      probe.jacobians(mj_states[s], Vector<double>(u), a_fd, b_fd);
      worst = sbptt::worst_error(
          {worst, (pi * a * pi.transpose() - a_fd).cwiseAbs().maxCoeff<Eigen::PropagateNaN>()});
    }
    std::printf("  eps %.0e: %.1e", eps, worst);
  }
  std::printf("\n");
}

}  // namespace

int main(int argc, char** argv) {
  long repeats = 5;
  std::string source = SBPTT_SOURCE_DIR;
  examples::CommandLine cli("bench_mujoco",
                            "per-step cost of MuJoCo (mj_step, mjd_transitionFD) against the "
                            "analytic cart pole, and the accuracy of its finite differences. Exit "
                            "codes: 0 success, 1 error, 2 bad flag.");
  cli.integer("--repeats", repeats, 1, 1000, "timed repeats per figure (the best is kept)");
  cli.path("--source", source, "the sbptt source tree (for tests/models and examples/models)",
           SBPTT_SOURCE_DIR);
  try {
    if (!cli.parse(argc, argv)) return examples::with_streams_checked("bench_mujoco", 0);
  } catch (const InvalidArgument& e) {
    std::fprintf(stderr, "bench_mujoco: %s\n", e.what());
    return 2;
  }
  try {
    const Models models = read_models(source);
    // MuJoCo's own code is Debian's build, whatever this program was compiled for.
    std::printf("instruction set: %s (sbptt's analytic rows; libmujoco is Debian's build)\n",
                instruction_set());
    std::printf("%-38s %10s %12s %10s   ratios to the analytic row\n", "simulator (double)",
                "step ns", "jacobians ns", "vjp ns");
    if (!examples::streams_written("bench_mujoco")) return 1;
    for (const Index poles : {1, 2})
      cartpole_rows(poles, *models.cartpole[poles - 1], static_cast<int>(repeats));
    const MujocoSimulator<double> sim(*models.double_pendulum);
    std::vector<Vector<double>> states;
    Rng rng(2);
    for (int s = 0; s < 64; ++s) {
      Vector<double> x = sim.initial_state();
      for (Index i = 0; i < x.size(); ++i) x(i) += rng.uniform(-1.0, 1.0);
      states.push_back(x);
    }
    print_row("double pendulum, MuJoCo", measure(sim, states, static_cast<int>(repeats)), nullptr);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_mujoco: %s\n", e.what());
    return 1;
  }
  return examples::with_streams_checked("bench_mujoco", 0);
}
