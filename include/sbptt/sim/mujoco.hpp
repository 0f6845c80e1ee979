#pragma once
/// \file A `Simulator` over any smooth MuJoCo model (`mjModel`, MuJoCo 2.2): the physics is
/// MuJoCo's, the derivatives are its finite differences.
///
/// Opt-in: this header and the two it includes (mujoco_model.hpp, mujoco_data_pool.hpp) are
/// the only ones that include `<mujoco/mujoco.h>`; `sbptt/sbptt.hpp` does not include it, and
/// a consumer links the CMake target `sbptt::mujoco` (which brings `mujoco::mujoco`) to use it.
///
/// State layout (size 2 nv + na): qpos (nq = nv entries), qvel (nv), act (na). Control: ctrl
/// (nu). Step: one `mj_step` with the model's own integrator and `opt.timestep` (MuJoCo's
/// `Euler` is semi-implicit: v' = v + h a(q, v, u), q' = q + h v').
///
/// Jacobians: `mjd_transitionFD` with centered differences of step `fd_step`,
///
///     A = ∂x'/∂x ≈ (P(x + ε e_j, u) − P(x − ε e_j, u)) / 2ε   (state_dim × state_dim)
///     B = ∂x'/∂u ≈ (P(x, u + ε e_j) − P(x, u − ε e_j)) / 2ε   (state_dim × nu)
///
/// so one call costs 2 (2 nv + na + nu) + 1 steps and is accurate to O(ε²) + O(δ/ε), δ the
/// rounding error of one step. The VJP forms A and B and returns Aᵀλ, Bᵀλ: the same cost.
/// With the RK4 integrator the same differences are taken of whole `mj_step`s instead (2 (2 nv
/// + na + nu) of them): MuJoCo 2.2's `mjd_transitionFD` skips stages that RK4's later stages
/// need recomputed, and its B had relative errors of up to 5.2e6 (docs/mujoco.md).
///
/// Refused: models whose qpos and qvel differ in size (free and ball joints hold a quaternion
/// in qpos and an angular velocity in qvel). `mjd_transitionFD` differentiates in the tangent
/// space (nv position coordinates), so A would not be ∂x'/∂x of the (qpos, qvel) state the
/// engine stores; mapping the tangent space correctly is not done here. Also refused: models
/// without an actuator (nothing for a controller to drive), and models with a NaN or ±Inf in
/// an option or array (named; MuJoCo only prints a warning, and one in the physics makes every
/// step NaN; user and display data are scanned too, so that no field needs sorting out).
///
/// Threads: the `mjModel` is read-only after construction; every call leases an `mjData`
/// from a pool for its whole duration, so no `mjData` is ever used by two threads at once and
/// the pool holds at most one per concurrent caller. Every call first writes the whole input
/// state (qpos, qvel, act, ctrl, time 0, warm start 0), so the result does not depend on which
/// `mjData` served it or what it computed before: 1 and N threads give bitwise equal results.
///
/// Failures: a step MuJoCo cannot take (a NaN or |value| > 1e10 in the state, control or
/// acceleration, or a full contact/constraint buffer, after which MuJoCo silently resets its
/// state) yields NaN in every output instead, as a diverging analytic simulator would, so the
/// engine's non-finite report names the step. So does `step` when its result holds such a
/// value (the last step of a rollout too, though MuJoCo would refuse it only when stepping from
/// it); the Jacobians there stay MuJoCo's differences, which no sweep asks for once the
/// forward pass has stopped on the NaN state. The adapter keeps MuJoCo from printing these
/// warnings or writing MUJOCO_LOG.TXT (see `arm_mujoco_warnings`), and records them instead:
/// `take_refusals()` says how many calls MuJoCo refused and why the first was ("its contact
/// buffer is full (increase nconmax above 100)"), and the trainer adds that to its non-finite
/// events. After a reset MuJoCo recomputes the rest state with its records zeroed, and prints
/// a warning raised there (a full contact buffer at rest); no call can keep that one silent.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <mujoco/mujoco.h>
#include <mujoco/mjxmacro.h>

#include "sbptt/core/error.hpp"
#include "sbptt/core/number_text.hpp"
#include "sbptt/core/types.hpp"
#include "sbptt/sim/mujoco_data_pool.hpp"
#include "sbptt/sim/mujoco_model.hpp"

namespace sbptt {

/// Settings of `MujocoSimulator`.
struct MujocoOptions {
  /// ε of the centered differences of A and B (absolute, in state and control units; in (0,
  /// 1]). MuJoCo's own suggestion is 1e-6.
  double fd_step = 1e-6;
};

namespace detail {

/// "name[i] is nan" for the first non-finite real number of the model (its options, then its
/// arrays, in MuJoCo's own list of them, mjxmacro.h), or empty. MuJoCo loads a NaN with only a
/// printed warning.
inline std::string first_non_finite_field(const mjModel& model) {
  std::string found;
  const auto scan = [&found](const char* name, const auto* values, long count) {
    if constexpr (std::is_floating_point_v<std::remove_cvref_t<decltype(*values)>>)
      for (long i = 0; i < count && found.empty(); ++i)
        if (!std::isfinite(values[i])) found = concat(name, "[", i, "] is ", values[i]);
  };
#define X(type, name) scan("opt." #name, &model.opt.name, 1);
  MJOPTION_FLOATS
#undef X
#define X(name, size) scan("opt." #name, model.opt.name, size);
  MJOPTION_VECTORS
#undef X
  const mjModel* m = &model;
  MJMODEL_POINTERS_PREAMBLE(m)
#define X(type, name, rows, columns) \
  scan(#name, model.name, static_cast<long>(model.rows) * (columns));
  MJMODEL_POINTERS
#undef X
  return found;
}

}  // namespace detail

/// A MuJoCo model as an sbptt `Simulator` (see the file comment for the state layout, the
/// derivatives and the threading). Copies share the model and the data pool; both are safe
/// to use from any number of threads.
template <class ScalarT = double>
class MujocoSimulator {
public:
  using Scalar = ScalarT;
  using State = Vector<Scalar>;            ///< (qpos, qvel, act): 2 nv + na
  using Control = Vector<Scalar>;          ///< ctrl: nu
  using StateJacobian = Matrix<Scalar>;    ///< (2 nv + na) × (2 nv + na)
  using ControlJacobian = Matrix<Scalar>;  ///< (2 nv + na) × nu

  /// Copies `model` (later changes to it do not reach the simulator). Throws InvalidArgument
  /// for a model with nq ≠ nv, without actuators, with an empty state, with a NaN or ±Inf, or a
  /// bad option.
  explicit MujocoSimulator(const mjModel& model, const MujocoOptions& options = {})
      : options_(options) {
    detail::require(model.nq == model.nv, "MujocoSimulator: the model has nq = ", model.nq,
                    " position coordinates but nv = ", model.nv,
                    " velocity coordinates (a free or ball joint: its orientation is a "
                    "quaternion in qpos and an angular velocity in qvel); the state (qpos, qvel, "
                    "act) and the tangent-space Jacobians of mjd_transitionFD would not match, "
                    "so only models of hinge and slide joints are supported");
    detail::require(model.nu >= 1, "MujocoSimulator: the model has no actuator (nu = 0), "
                                   "so a controller has nothing to drive; expected nu >= 1");
    detail::require(model.nv + model.na >= 1,
                    "MujocoSimulator: the model has no joint (nv = 0) and no actuator activation "
                    "(na = 0), so its state is empty; expected at least one hinge or slide joint, "
                    "or an actuator with activation dynamics");
    // Past 1 a difference is no derivative, and probes past MuJoCo's bound of 1e10 make it
    // reset the mjData, after which its warnings print.
    detail::require(std::isfinite(options.fd_step) && options.fd_step > 0 &&
                        options.fd_step <= 1,
                    "MujocoSimulator: fd_step = ", options.fd_step,
                    ", expected a finite ε in (0, 1]");
    const std::string non_finite = detail::first_non_finite_field(model);
    detail::require(non_finite.empty(), "MujocoSimulator: the model's ", non_finite,
                    "; expected finite numbers in all its options and arrays");
    detail::require(model.opt.timestep > 0, "MujocoSimulator: the model's timestep = ",
                    model.opt.timestep, ", expected > 0");
    mjModel* copy = mj_copyModel(nullptr, &model);
    detail::require(copy != nullptr, "MujocoSimulator: mj_copyModel could not copy the model");
    model_ = std::shared_ptr<const mjModel>(copy, MujocoModelDeleter{});
    pool_ = std::make_shared<detail::MujocoDataPool>(model_);
    nv_ = model.nv;
    na_ = model.na;
    nu_ = model.nu;
  }

  /// The simulator's own copy of the model (read-only).
  [[nodiscard]] const mjModel& model() const { return *model_; }
  [[nodiscard]] const MujocoOptions& options() const { return options_; }
  [[nodiscard]] Index state_dim() const { return 2 * nv_ + na_; }
  [[nodiscard]] Index control_dim() const { return nu_; }
  [[nodiscard]] Scalar dt() const { return static_cast<Scalar>(model_->opt.timestep); }

  /// The model's rest state: (qpos0, 0, 0) (state_dim).
  [[nodiscard]] State initial_state() const {
    State x = State::Zero(state_dim());
    for (Index i = 0; i < nv_; ++i) x(i) = static_cast<Scalar>(model_->qpos0[i]);
    return x;
  }

  /// x_next = one mj_step from (x, u). x, x_next: state_dim; u: control_dim.
  void step(const State& x, const Control& u, State& x_next) const {
    check_sizes(x, u);
    auto slot = pool_->lease();
    x_next.resize(state_dim());
    mjData& d = *slot->data;
    Refusal refusal = refusal_of_input(x, u);
    if (!refusal.refused) {
      write_input(x, u, d);
      mj_step(model_.get(), &d);
      refusal = refusal_of_step(d);
    }
    if (refusal.refused) {
      note(std::move(refusal));
      x_next.setConstant(nan());
      return;
    }
    read_state(d, x_next);
  }

  /// A = ∂x_next/∂x (state_dim × state_dim), B = ∂x_next/∂u (state_dim × control_dim), by
  /// centered finite differences of mj_step (`mjd_transitionFD`, or whole steps for RK4; step
  /// `options().fd_step`).
  void jacobians(const State& x, const Control& u, StateJacobian& a, ControlJacobian& b) const {
    check_sizes(x, u);
    auto slot = pool_->lease();
    const auto [a_row_major, b_row_major] = transition_jacobians(x, u, *slot);
    a = a_row_major.template cast<Scalar>();
    b = b_row_major.template cast<Scalar>();
  }

  /// *lambda_x = Aᵀ λ (state_dim), *lambda_u = Bᵀ λ (control_dim), from the finite-difference
  /// A and B (one `jacobians` call). Either pointer may be null to skip that product.
  void vjp(const State& x, const Control& u, const State& lambda, State* lambda_x,
           Control* lambda_u) const {
    check_sizes(x, u);
    detail::require(lambda.size() == state_dim(), "MujocoSimulator: lambda has size ",
                    lambda.size(), ", expected state_dim() = ", state_dim());
    if (lambda_x == nullptr && lambda_u == nullptr) return;
    auto slot = pool_->lease();
    const auto [a, b] = transition_jacobians(x, u, *slot);
    const auto& adjoint = lambda.template cast<mjtNum>();  // an expression, or λ itself
    if (lambda_x != nullptr) *lambda_x = (a.transpose() * adjoint).template cast<Scalar>();
    if (lambda_u != nullptr) *lambda_u = (b.transpose() * adjoint).template cast<Scalar>();
  }

  /// The calls that MuJoCo refused (each answered with NaN) since the last `take_refusals`,
  /// by this simulator and its copies on any thread, and why the first was refused; forgets
  /// them. `describe` puts the record in words; the trainer adds them to its non-finite
  /// events (`ExplainsRefusals`). With threads, which refusal came first may vary.
  [[nodiscard]] MujocoRefusals take_refusals() const { return pool_->take_refusals(); }

private:
  using RowMajorMap = Eigen::Map<const RowMajorMatrix<mjtNum>>;
  using WritableRowMajorMap = Eigen::Map<RowMajorMatrix<mjtNum>>;
  using ColumnMap = Eigen::Map<const Vector<mjtNum>>;
  struct TransitionJacobians {
    RowMajorMap a, b;
  };

  [[nodiscard]] static Scalar nan() { return std::numeric_limits<Scalar>::quiet_NaN(); }

  void check_sizes(const State& x, const Control& u) const {
    detail::require(x.size() == state_dim(), "MujocoSimulator: x has size ", x.size(),
                    ", expected state_dim() = 2 nv + na = ", state_dim());
    detail::require(u.size() == control_dim(), "MujocoSimulator: u has size ", u.size(),
                    ", expected control_dim() = nu = ", control_dim());
  }

  /// Whether MuJoCo refuses a call, and why; `why` is empty for a NaN or ±Inf in the input,
  /// which came from elsewhere (see mujoco_data_pool.hpp).
  struct Refusal {
    bool refused = false;
    std::string why;
  };

  void note(Refusal refusal) const {
    if (!refusal.why.empty()) pool_->record_refusal(std::move(refusal.why));
  }

  /// "qpos[1]", "qvel[0]" or "act[2]": entry i of the state.
  [[nodiscard]] std::string state_entry(Index i) const {
    if (i < nv_) return detail::concat("qpos[", i, "]");
    if (i < 2 * nv_) return detail::concat("qvel[", i - nv_, "]");
    return detail::concat("act[", i - 2 * nv_, "]");
  }

  /// "<what> is 2e+10, beyond MuJoCo's bound of 1e+10", or "<what> is nan".
  [[nodiscard]] static std::string refused_value(const std::string& what, mjtNum value) {
    std::string text = what + " is " + detail::shortest(value);
    if (std::isfinite(value)) text += ", beyond MuJoCo's bound of " + detail::shortest(mjMAXVAL);
    return text;
  }

  /// MuJoCo refuses (without stepping) an input with a NaN, ±Inf or a value beyond mjMAXVAL.
  [[nodiscard]] Refusal refusal_of_input(const State& x, const Control& u) const {
    const auto refusal = [](const std::string& what, mjtNum value) {
      return Refusal{true, std::isfinite(value) ? refused_value(what, value) : std::string()};
    };
    for (Index i = 0; i < x.size(); ++i)
      if (mju_isBad(static_cast<mjtNum>(x(i))))
        return refusal("the state's " + state_entry(i), static_cast<mjtNum>(x(i)));
    for (Index i = 0; i < u.size(); ++i)
      if (mju_isBad(static_cast<mjtNum>(u(i))))
        return refusal(detail::concat("the control's ctrl[", i, "]"), static_cast<mjtNum>(u(i)));
    return {};
  }

  /// Writes state `x` (qpos, qvel, act: anything indexed by [i]) and control `u` into `d`, time
  /// and warm start zeroed, warnings armed: the whole input of a step, so that its result does
  /// not depend on what `d` computed before.
  template <class StateValues, class ControlValues>
  void write_input(const StateValues& x, const ControlValues& u, mjData& d) const {
    for (Index i = 0; i < nv_; ++i) {
      d.qpos[i] = static_cast<mjtNum>(x[i]);
      d.qvel[i] = static_cast<mjtNum>(x[nv_ + i]);
      d.qacc_warmstart[i] = 0;
    }
    for (Index i = 0; i < na_; ++i) d.act[i] = static_cast<mjtNum>(x[2 * nv_ + i]);
    for (Index i = 0; i < nu_; ++i) d.ctrl[i] = static_cast<mjtNum>(u[i]);
    d.time = 0;
    detail::arm_mujoco_warnings(d);
  }

  /// Why the step just taken in `d` does not stand, if it does not: MuJoCo raised a failure,
  /// or its result holds a value MuJoCo would refuse (it checks a state only when it steps from
  /// it; the last state of a rollout never is).
  [[nodiscard]] Refusal refusal_of_step(const mjData& d) const {
    if (std::string warning = detail::mujoco_failure(d); !warning.empty())
      return {true, std::move(warning)};
    for (Index i = 0; i < state_dim(); ++i) {
      const mjtNum value = i < nv_ ? d.qpos[i] : i < 2 * nv_ ? d.qvel[i - nv_] : d.act[i - 2 * nv_];
      if (mju_isBad(value))
        return {true, refused_value("the step's result " + state_entry(i), value)};
    }
    return {};
  }

  /// The state of `d` (qpos, qvel, act) into `out` (anything indexed by [i]).
  template <class StateValues>
  void read_state(const mjData& d, StateValues& out) const {
    using Value = std::remove_cvref_t<decltype(out[0])>;
    for (Index i = 0; i < nv_; ++i) {
      out[i] = static_cast<Value>(d.qpos[i]);
      out[nv_ + i] = static_cast<Value>(d.qvel[i]);
    }
    for (Index i = 0; i < na_; ++i) out[2 * nv_ + i] = static_cast<Value>(d.act[i]);
  }

  /// Fills the slot's row-major A and B (NaN if MuJoCo rejected any probe) and maps them.
  TransitionJacobians transition_jacobians(const State& x, const Control& u,
                                           detail::MujocoSlot& slot) const {
    const Index n = state_dim();
    TransitionJacobians out{RowMajorMap(slot.state_jacobian.data(), n, n),
                            RowMajorMap(slot.control_jacobian.data(), n, nu_)};
    Refusal refusal = refusal_of_input(x, u);
    if (!refusal.refused) {
      write_input(x, u, *slot.data);
      if (model_->opt.integrator == mjINT_RK4) {
        refusal = whole_step_differences(slot);
      } else {
        mjd_transitionFD(model_.get(), slot.data.get(), options_.fd_step, 1,
                         slot.state_jacobian.data(), slot.control_jacobian.data(), nullptr,
                         nullptr);
        refusal.why = detail::mujoco_failure(*slot.data);
        refusal.refused = !refusal.why.empty();
      }
    }
    if (refusal.refused) {
      note(std::move(refusal));
      constexpr mjtNum not_a_number = std::numeric_limits<mjtNum>::quiet_NaN();
      std::fill(slot.state_jacobian.begin(), slot.state_jacobian.end(), not_a_number);
      std::fill(slot.control_jacobian.begin(), slot.control_jacobian.end(), not_a_number);
    }
    return out;
  }

  /// The slot's A and B by centered differences of whole `mj_step`s from the state loaded in
  /// its mjData, each probe loaded afresh; why MuJoCo refused the first probe it refused, if
  /// any. For RK4 only: MuJoCo 2.2's `mjd_transitionFD` reuses the unperturbed state's position
  /// and velocity stages in RK4's three later stages, which gave B off by up to 5.2e6
  /// (relative) on a cart with a double pendulum (tests/test_sim_mujoco.cpp). Whole steps redo
  /// the stages that `mjd_transitionFD` skips, in as many steps.
  Refusal whole_step_differences(detail::MujocoSlot& slot) const {
    mjData& d = *slot.data;
    const Index n = state_dim();
    read_state(d, slot.probe);
    std::copy(d.ctrl, d.ctrl + nu_, slot.probe.begin() + n);
    Refusal refusal;
    const auto step_from_probe = [&](std::vector<mjtNum>& next) {
      write_input(slot.probe, slot.probe.data() + n, d);
      mj_step(model_.get(), &d);
      if (!refusal.refused) refusal = refusal_of_step(d);
      read_state(d, next);
    };
    const mjtNum eps = options_.fd_step;
    for (Index j = 0; j < n + nu_; ++j) {
      const mjtNum centre = slot.probe[static_cast<std::size_t>(j)];
      slot.probe[static_cast<std::size_t>(j)] = centre + eps;
      step_from_probe(slot.plus);
      slot.probe[static_cast<std::size_t>(j)] = centre - eps;
      step_from_probe(slot.minus);
      slot.probe[static_cast<std::size_t>(j)] = centre;
      const auto slope = (ColumnMap(slot.plus.data(), n) - ColumnMap(slot.minus.data(), n)) /
                         (2 * eps);
      if (j < n) {
        WritableRowMajorMap(slot.state_jacobian.data(), n, n).col(j) = slope;
      } else {
        WritableRowMajorMap(slot.control_jacobian.data(), n, nu_).col(j - n) = slope;
      }
    }
    return refusal;
  }

  std::shared_ptr<const mjModel> model_;
  std::shared_ptr<detail::MujocoDataPool> pool_;
  MujocoOptions options_;
  Index nv_ = 0, na_ = 0, nu_ = 0;
};

}  // namespace sbptt
