// Any smooth MuJoCo model (MJCF) as a task: the stock MLP controller (input: the state
// (qpos, qvel, act); output: ctrl) learns to bring qpos to a target at the final step, from
// initial states around the model's qpos0. Physics and its Jacobians are MuJoCo's
// (sbptt/sim/mujoco.hpp: mj_step, mjd_transitionFD); see docs/mujoco.md.
//   mujoco --model examples/models/double_pendulum.xml --target 3.14159,0 --method C
//   mujoco --model scene.xml --check-derivatives
//
// Loss at the final step, per position coordinate i with target t_i:
//   hinge joint: 1 − cos(q_i − t_i)   (2π apart is the same pose; ≈ ½ (q_i − t_i)²)
//   slide joint: ½ (q_i − t_i)²
// Initial states: qpos = qpos0 + U[−spread, spread) per coordinate, qvel = 0, act = 0.
// The time step is the model's (opt.timestep) unless --dt or --T are given; --steps defaults
// to 100. `mujoco --help` lists every flag.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <type_traits>
#include <vector>

#include <sbptt/sim/mujoco.hpp>

#include "task_program.hpp"

using namespace sbptt;
using sbptt::examples::Task;
using sbptt::examples::TaskOptions;

namespace {

/// Whether qpos coordinate i is a hinge angle (compared modulo 2π), per qpos entry.
std::vector<bool> hinge_coordinates(const mjModel& model) {
  std::vector<bool> hinge(static_cast<std::size_t>(model.nq), false);
  for (int j = 0; j < model.njnt; ++j)
    if (model.jnt_type[j] == mjJNT_HINGE)
      hinge[static_cast<std::size_t>(model.jnt_qposadr[j])] = true;
  return hinge;
}

/// "slider (slide), hinge1 (hinge)": the position coordinates, for error messages.
std::string describe_coordinates(const mjModel& model) {
  std::string text;
  for (int j = 0; j < model.njnt; ++j) {
    const char* name = model.names + model.name_jntadr[j];
    if (!text.empty()) text += ", ";
    text += (*name != '\0' ? std::string(name) : "joint " + std::to_string(j)) +
            (model.jnt_type[j] == mjJNT_HINGE ? " (hinge)" : " (slide)");
  }
  return text;
}

/// --target as a vector; throws naming the flag, the value and the model's coordinates unless
/// it holds nq numbers, and naming the model if it has no position (nq = 0) to aim at.
Vector<double> target_positions(const std::vector<double>& values, const mjModel& model,
                                const std::string& file) {
  detail::require(model.nq >= 1, "'", file, "' has no position coordinate (nq = 0), so --target ",
                  "has nothing to aim at; expected a model with at least one hinge or slide joint");
  detail::require(!values.empty(), "--target is required: ", model.nq,
                  " comma-separated positions, one per coordinate of '", file, "': ",
                  describe_coordinates(model));
  detail::require(static_cast<int>(values.size()) == model.nq, "--target '",
                  examples::comma_separated(values), "' has ", values.size(),
                  " value(s); expected nq = ", model.nq, ", one per position coordinate of '", file,
                  "': ", describe_coordinates(model));
  return Eigen::Map<const Vector<double>>(values.data(), static_cast<Index>(values.size()));
}

/// ℓ(x) at the final step: 1 − cos(q_i − t_i) on hinges, ½ (q_i − t_i)² on slides, summed
/// over the nq position coordinates (the first nq entries of the state).
template <class Scalar>
struct TargetLoss {
  Vector<Scalar> target;   ///< nq
  std::vector<bool> hinge;  ///< nq

  Scalar operator()(const Vector<Scalar>& x, Vector<Scalar>* grad) const {
    using std::cos, std::sin;
    if (grad != nullptr) grad->setZero(x.size());
    Scalar loss(0);
    for (Index i = 0; i < target.size(); ++i) {
      const Scalar d = x(i) - target(i);
      const bool angle = hinge[static_cast<std::size_t>(i)];
      loss += angle ? Scalar(1) - cos(d) : Scalar(0.5) * d * d;
      if (grad != nullptr) (*grad)(i) = angle ? sin(d) : d;
    }
    return loss;
  }
};

template <class Scalar>
Matrix<Scalar> initial_states(const MujocoSimulator<Scalar>& sim, double spread, Rng& rng,
                              Index count) {
  const Vector<Scalar> rest = sim.initial_state();
  Matrix<Scalar> states(sim.state_dim(), count);
  for (Index j = 0; j < count; ++j) {
    states.col(j) = rest;
    for (Index i = 0; i < sim.model().nq; ++i)
      states(i, j) += static_cast<Scalar>(rng.uniform(-spread, spread));
  }
  return states;
}

/// --check-derivatives: check_jacobians (mjd_transitionFD and the VJP against sbptt's own
/// central differences of mj_step) at five initial states with controls U[−1, 1), and a verdict
/// against the tolerance a smooth model meets.
template <class Scalar>
int check_derivatives(const MujocoSimulator<Scalar>& sim, const TaskOptions& o, Rng& rng) {
  const Matrix<Scalar> states = initial_states(sim, o.spread, rng, 5);
  JacobianCheck<Scalar> worst;  // each error the worst over the states
  JacobianCheck<Scalar> worst_state;  // the state of the worst error
  Index worst_at = 0;
  for (Index j = 0; j < states.cols(); ++j) {
    Vector<Scalar> u(sim.control_dim());
    for (Index k = 0; k < u.size(); ++k) u(k) = static_cast<Scalar>(rng.uniform(-1.0, 1.0));
    const auto check = check_jacobians(sim, Vector<Scalar>(states.col(j)), u);
    worst.state_jacobian_error =
        worst_error({worst.state_jacobian_error, check.state_jacobian_error});
    worst.control_jacobian_error =
        worst_error({worst.control_jacobian_error, check.control_jacobian_error});
    worst.vjp_error = worst_error({worst.vjp_error, check.vjp_error});
    if (j == 0 || (!std::isnan(worst_state.worst()) && !(check.worst() <= worst_state.worst()))) {
      worst_state = check;
      worst_at = j + 1;
    }
  }
  const auto a = static_cast<double>(worst.state_jacobian_error);
  const auto b = static_cast<double>(worst.control_jacobian_error);
  const auto vjp = static_cast<double>(worst.vjp_error);
  std::printf("mujoco: %s: worst relative error at 5 states: A %.3g, B %.3g, VJP %.3g\n",
              o.model.c_str(), a, b, vjp);
  const std::string where = detail::concat(
      "The worst, at state ", worst_at, " of 5: ", describe(worst_state),
      " (rows and columns from 0; the state is qpos, qvel, act)");
  // An error that is not finite checked nothing: the step or its derivatives were NaN, or too
  // large to compare, at one of the states, which a printed line with exit 0 would hide.
  if (!std::isfinite(worst.worst())) {
    const std::string note = detail::note_after(": ", detail::take_refusal_note(sim));
    std::fprintf(stderr, "mujoco: %s: an error is not finite: the step or its derivatives are "
                 "NaN or too large to compare at one of the 5 states%s; expected finite "
                 "errors (check the model's values). %s\n", o.model.c_str(),
                 note.c_str(), where.c_str());
    return 3;
  }
  const auto tolerance = static_cast<double>(JacobianCheck<Scalar>::smooth_tolerance());
  const char* scalar = std::is_same_v<Scalar, float> ? "float" : "double";
  if (worst.worst() < JacobianCheck<Scalar>::smooth_tolerance()) {
    std::printf("mujoco: %s: below the tolerance %g of a smooth model in %s: the derivatives "
                "agree\n", o.model.c_str(), tolerance, scalar);
    return 0;
  }
  // Two differences of the same step disagree where it is not smooth at the scale of their
  // steps; a gradient through it would be noise (docs/mujoco.md).
  std::fprintf(stderr, "mujoco: %s: above the tolerance %g of a smooth model in %s (A %.3g, B "
               "%.3g, VJP %.3g): the derivatives disagree; expected errors below %g (a contact, "
               "limit or friction that switches within the differences, or a stiff model, makes "
               "them disagree: docs/mujoco.md). %s\n",
               o.model.c_str(), tolerance, scalar, a, b, vjp, tolerance, where.c_str());
  return 3;
}

template <class Scalar>
int run(TaskOptions o) {
  detail::require(!o.model.empty(), "--model is required: the MJCF file of the scene");
  std::vector<std::string> warnings;
  const MujocoModelPtr model =
      detail::prefixing_errors("--model", [&] { return load_mujoco_model(o.model, &warnings); });
  for (const std::string& warning : warnings)
    std::fprintf(stderr, "mujoco: --model '%s': MuJoCo warns: %s\n", o.model.c_str(),
                 warning.c_str());
  o.time = examples::resolve_mujoco_time(o, model->opt.timestep);
  model->opt.timestep = o.time.dt;
  const MujocoSimulator<Scalar> sim = detail::prefixing_errors(
      detail::concat("--model '", o.model, "'"), [&] { return MujocoSimulator<Scalar>(*model); });
  Rng data_rng(o.seed);
  if (o.check_derivatives) return check_derivatives(sim, o, data_rng);
  const Vector<double> target = target_positions(o.positions, *model, o.model);
  auto network = Network<Scalar>::mlp(sim.state_dim(), {100, 100}, sim.control_dim());
  Rng init_rng(o.seed + 1);
  glorot_uniform(network, init_rng, {.zero_last_kernel = true});
  auto data = examples::generated_sets<Scalar>(o, sim.state_dim(), network, [&](Index count) {
    return initial_states(sim, o.spread, data_rng, count);
  });
  Objective<TargetLoss<Scalar>> objective;
  objective.state_loss = {target.cast<Scalar>(), hinge_coordinates(*model)};
  objective.timing = LossTiming::Final;
  return examples::train(o, sim, network, objective, o.time.steps, std::move(data));
}

}  // namespace

int main(int argc, char** argv) {
  return examples::task_main(Task::Mujoco, argc, argv, []<class Scalar>(const TaskOptions& o) {
    return run<Scalar>(o);
  });
}
