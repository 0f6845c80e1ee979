// The paper's quantum control task (docs/paper.md §6): a field u(t) · x drives a particle in a 1-D
// well from a superposition of the two lowest states to an excited state. The CNN of the
// reference (conv k3 s2 ×2, 60 channels, dense) with a random last layer; loss: summed
// infidelity over 128 steps. --target counts as the paper's plots (0 = ground state).
//   quantum --target 3 --method C --epochs 20 --csv out.csv
#include "task_program.hpp"

using namespace sbptt;
using sbptt::examples::Task;
using sbptt::examples::TaskOptions;

template <class Scalar, int Nx>
int run(const TaskOptions& o) {
  SchrodingerOptions<Scalar> options;
  options.dt = static_cast<Scalar>(o.time.dt);
  options.steps = o.time.steps;
  const Schrodinger1D<Scalar, Nx> sim(o.nx, options);
  Rng data_rng(o.seed);
  const Conv1d first{o.nx, 2, 60, 3, 2, Activation::Tanh};
  const Conv1d second{first.output_length(), 60, 60, 3, 2, Activation::Tanh};
  Network<Scalar> network({first, second, Dense{second.output_length() * 60, 1}});
  // The reference's first layer is a Keras Conv2D with a (3, 2) kernel over (Nx, 2, 1): the
  // same function, but Glorot fans (6, 360) instead of our conv1d's (6, 180).
  Rng init_rng(o.seed + 1);
  glorot_uniform(network, init_rng, {.fan_overrides = {std::pair<Index, Index>{6, 360}}});
  auto data = examples::generated_sets<Scalar>(o, sim.state_dim(), network, [&](Index count) {
    return sim.initial_states(data_rng, count);
  });
  return examples::train(o, sim, network, quantum_objective(sim, o.target + 1), o.time.steps,
                         std::move(data));
}

int main(int argc, char** argv) {
  return examples::task_main(Task::Quantum, argc, argv, []<class Scalar>(const TaskOptions& o) {
    if (o.nx == 32) return run<Scalar, 32>(o);
    return run<Scalar, Eigen::Dynamic>(o);
  });
}
