// The paper's guidance-by-repulsion (herding) task (docs/paper.md §4): drivers, steered by radial and
// tangential gains, herd evaders to the origin. MLP 2×100 tanh with a zeroed last kernel;
// loss: mean squared evader distance over time plus rc · mean(control²).
//   guidance --rc 0.01 --method C --epochs 50 --csv out.csv
//   guidance --physical    centroid instead of the sum of evader positions, flocking as intended
#include "task_program.hpp"

using namespace sbptt;
using sbptt::examples::Task;
using sbptt::examples::TaskOptions;

template <class Scalar, int Drivers, int Evaders>
int run(const TaskOptions& o) {
  GuidanceOptions options;
  options.horizon = o.time.horizon();
  options.steps = o.time.steps;
  if (o.physical) options.physical = {GuidanceCenter::Centroid, FlockingSign::AsIntended};
  const GuidanceByRepulsion<Scalar, Drivers, Evaders> sim(o.drivers, o.evaders, options);
  Rng data_rng(o.seed);
  auto network = Network<Scalar>::mlp(sim.state_dim(), {100, 100}, sim.control_dim());
  Rng init_rng(o.seed + 1);
  glorot_uniform(network, init_rng, {.zero_last_kernel = true});
  auto data = examples::generated_sets<Scalar>(o, sim.state_dim(), network, [&](Index count) {
    return guidance_initial_states(sim, data_rng, count);
  });
  return examples::train(o, sim, network, guidance_objective(sim, o.rc), o.time.steps,
                         std::move(data));
}

int main(int argc, char** argv) {
  return examples::task_main(Task::Guidance, argc, argv, []<class Scalar>(const TaskOptions& o) {
    // The paper's 2 drivers and 4 evaders get fixed sizes; other counts run dynamic.
    if (o.drivers == 2 && o.evaders == 4) return run<Scalar, 2, 4>(o);
    return run<Scalar, Eigen::Dynamic, Eigen::Dynamic>(o);
  });
}
