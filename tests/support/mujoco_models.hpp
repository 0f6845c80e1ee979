#pragma once
// The MuJoCo models of the adapter's tests: our cart pole as MJCF (tests/models/), and scenes
// written on the fly.
#include <filesystem>
#include <fstream>
#include <string>

#include "sbptt/sim/mujoco.hpp"

namespace sbptt::testing {

inline std::string model_path(int poles) {
  return std::string(SBPTT_SOURCE_DIR) + "/tests/models/cartpole_physical_" +
         std::to_string(poles) + ".xml";
}

/// The MJCF cart pole with its timestep (and optionally integrator) replaced.
inline MujocoSimulator<double> mujoco_cartpole(int poles, double timestep,
                                               int integrator = mjINT_EULER) {
  const MujocoModelPtr model = load_mujoco_model(model_path(poles));
  model->opt.timestep = timestep;
  model->opt.integrator = integrator;
  return MujocoSimulator<double>(*model);
}

/// Writes `text` to a file in the temporary directory and returns its path.
inline std::string write_temp_model(const std::string& name, const std::string& text) {
  const auto path = std::filesystem::temp_directory_path() / ("sbptt_test_mujoco_" + name);
  std::ofstream(path) << text;
  return path.string();
}

}  // namespace sbptt::testing
