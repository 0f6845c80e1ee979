// Smallest downstream program of the MuJoCo adapter, through the installed headers and the
// sbptt::mujoco target: loads the MJCF file given as the argument and checks the adapter's
// Jacobians (mjd_transitionFD) against sbptt's own central differences of its step, at the
// model's rest state tilted by 0.3 in every position coordinate. Exits non-zero unless they
// agree to 1e-6.
#include <cstdio>
#include <exception>

#include <sbptt/core/finite_difference.hpp>
#include <sbptt/sim/mujoco.hpp>

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: consumer_mujoco MODEL.xml\n");
    return 2;
  }
  try {
    const sbptt::MujocoModelPtr model = sbptt::load_mujoco_model(argv[1]);
    const sbptt::MujocoSimulator<double> sim(*model);
    sbptt::Vector<double> x = sim.initial_state();
    x.head(model->nq).array() += 0.3;
    const sbptt::Vector<double> u = sbptt::Vector<double>::Constant(sim.control_dim(), 0.5);
    const auto check = sbptt::check_jacobians(sim, x, u);
    std::printf("state_dim %ld, worst Jacobian error %.3g (expected < 1e-6)\n",
                static_cast<long>(sim.state_dim()), static_cast<double>(check.worst()));
    return check.worst() < 1e-6 ? 0 : 1;
  } catch (const std::exception& error) {
    std::fprintf(stderr, "consumer_mujoco: %s\n", error.what());
    return 1;
  }
}
