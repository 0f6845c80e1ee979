#pragma once
/// \file Guidance by repulsion ("herding", paper §4): drivers steer evaders by repelling them.
///
/// Agents move in the plane; p, v are an agent's position and velocity; dist(r) = ε + ‖r‖.
/// Accelerations (defaults in brackets):
///
///   driver d:  p̈_d = F_con,d + F_spread,d − γ_D v_d                                   [γ_D = 1]
///     F_con,d    = c_{d,0} r_d + c_{d,1} r_d⊥,  r_d = p_d − S,  r⊥ = (−r_y, r_x)
///                  S = Σ_e p_e (GuidanceCenter::Sum, the reference) or mean_e p_e (Centroid);
///                  c_{d,0} is a radial, c_{d,1} a tangential gain about S.
///     F_spread,d = κ_S Σ_{k≠d} (p_d − p_k) / dist(p_d − p_k)²                          [κ_S = 0.2]
///                  drivers repel each other, so they do not collapse onto one spot.
///   evader e:  p̈_e = F_rep,e + F_flock,e − γ_E v_e                                   [γ_E = 4]
///     F_rep,e    = κ_R Σ_d (p_e − p_d) / dist(p_d − p_e)²                              [κ_R = 15]
///                  the only way the drivers act on the evaders (no reaction on drivers).
///     F_flock,e  = σ κ_F Σ_{i≠e} f(δ_ie) (p_i − p_e),  δ_ie = δ₀ + ‖p_i − p_e‖,
///                  f(δ) = (ρ_F/δ − 1)/δ                      [κ_F = 0.2, δ₀ = 0.1, ρ_F = 0.5]
///                  σ = +1 (FlockingSign::AsCoded, the reference): attraction while f > 0, i.e.
///                  ‖p_i − p_e‖ < 0.4, repulsion beyond; σ = −1 (AsIntended): the code
///                  comment's "stay close but not too close", repulsion near, attraction far.
///   The reference's driver-to-evader attraction F_driving is switched off there and left out.
///
/// Integrator: explicit Euler on u = (p, v): p' = p + dt v, v' = v + dt p̈(p, v, c); dt = T/Nt
/// [T = 4, Nt = 60]. State layout: drivers first, then evaders; per agent p_x, p_y, v_x, v_y
/// (size 4(D + E)). Control layout: c_{0,0}, c_{0,1}, c_{1,0}, c_{1,1}, … (size 2D).
///
/// A term that cannot act costs nothing: no spreading loop with one driver, no flocking loop
/// with one evader. The options, the pair forces and their Jacobians are in
/// `guidance_forces.hpp`, with how two agents on the same spot are handled (finite values,
/// continuous Jacobians).
#include <cmath>
#include <numbers>

#include <Eigen/Core>

#include "sbptt/core/error.hpp"
#include "sbptt/core/rng.hpp"
#include "sbptt/core/types.hpp"
#include "sbptt/sim/guidance_forces.hpp"

namespace sbptt {

namespace detail {
constexpr int guidance_agents(int drivers, int evaders) {
  return drivers == Eigen::Dynamic || evaders == Eigen::Dynamic ? Eigen::Dynamic
                                                                : drivers + evaders;
}
constexpr int times_or_dynamic(int factor, int count) {
  return count == Eigen::Dynamic ? Eigen::Dynamic : factor * count;
}
}  // namespace detail

/// The guidance-by-repulsion scene (equations and layouts in the file comment).
///
/// `Drivers` and `Evaders` fix the agent counts at compile time; with `Eigen::Dynamic` they are
/// constructor arguments. Immutable and thread-safe: every member function is `const`.
template <class ScalarT = double, int Drivers = 2, int Evaders = 4>
class GuidanceByRepulsion {
  static_assert(Drivers == Eigen::Dynamic || Drivers >= 1, "needs at least one driver");
  static_assert(Evaders == Eigen::Dynamic || Evaders >= 1, "needs at least one evader");
  static constexpr int kAgents = detail::guidance_agents(Drivers, Evaders);

public:
  using Scalar = ScalarT;
  using Options = GuidanceOptions;
  static constexpr int kStateSize = detail::times_or_dynamic(4, kAgents);
  static constexpr int kControlSize = detail::times_or_dynamic(2, Drivers);
  using State = Eigen::Matrix<Scalar, kStateSize, 1>;                     ///< 4(D + E)
  using Control = Eigen::Matrix<Scalar, kControlSize, 1>;                 ///< 2D
  using StateJacobian = Eigen::Matrix<Scalar, kStateSize, kStateSize>;    ///< 4(D+E) × 4(D+E)
  using ControlJacobian = Eigen::Matrix<Scalar, kStateSize, kControlSize>;  ///< 4(D+E) × 2D

  /// Fixed agent counts. Throws InvalidArgument on a bad option.
  explicit GuidanceByRepulsion(const Options& options = {})
    requires(Drivers != Eigen::Dynamic && Evaders != Eigen::Dynamic)
      : GuidanceByRepulsion(Drivers, Evaders, options) {}

  /// Agent counts at run time (must equal the template's where those are fixed). Throws
  /// InvalidArgument on a bad count or option.
  GuidanceByRepulsion(Index drivers, Index evaders, const Options& options = {})
      : drivers_(drivers), evaders_(evaders), options_(options) {
    const char* who = "GuidanceByRepulsion: ";
    detail::require(drivers >= 1 && (Drivers == Eigen::Dynamic || drivers == Drivers), who,
                    "drivers = ", drivers, ", expected >= 1 and equal to the template's ",
                    Drivers, " unless that is Eigen::Dynamic");
    detail::require(evaders >= 1 && (Evaders == Eigen::Dynamic || evaders == Evaders), who,
                    "evaders = ", evaders, ", expected >= 1 and equal to the template's ",
                    Evaders, " unless that is Eigen::Dynamic");
    detail::validate_guidance_options(options);
    const auto flocking = options.physical.flocking;
    // Through NumTraits' Literal (float for a float dual number): one rounding, no warning.
    const auto cast = [](double v) {
      return static_cast<Scalar>(static_cast<typename Eigen::NumTraits<Scalar>::Literal>(v));
    };
    dt_ = cast(options.horizon / static_cast<double>(options.steps));
    epsilon_ = cast(options.epsilon);
    driver_friction_ = cast(options.driver_friction);
    evader_friction_ = cast(options.evader_friction);
    spreading_ = cast(options.spreading_gain);
    repulsion_ = cast(options.repulsion_gain);
    // As coded, evader e feels +κ_F f (p_i − p_e) = −κ_F K(p_e − p_i) with K(r) = f r.
    flocking_ = cast(flocking == FlockingSign::AsCoded ? -options.flocking_gain
                                                       : options.flocking_gain);
    flocking_offset_ = cast(options.flocking_offset);
    flocking_range_ = cast(options.flocking_range);
    center_weight_ = options.physical.center == GuidanceCenter::Sum
                         ? Scalar(1)
                         : Scalar(1) / cast(static_cast<double>(evaders));
  }

  [[nodiscard]] Index drivers() const { return drivers_; }
  [[nodiscard]] Index evaders() const { return evaders_; }
  [[nodiscard]] Index agents() const { return drivers_ + evaders_; }
  [[nodiscard]] Index state_dim() const { return 4 * agents(); }
  [[nodiscard]] Index control_dim() const { return 2 * drivers_; }
  [[nodiscard]] Scalar dt() const { return dt_; }
  [[nodiscard]] Index steps() const { return options_.steps; }
  [[nodiscard]] const Options& options() const { return options_; }

  /// x_next = P(x, u). x, x_next: state_dim; u: control_dim. `x_next` may alias `x`.
  void step(const State& x, const Control& u, State& x_next) const {
    check_sizes(x, u);
    Accelerations acc;
    accelerations(x, u, acc);
    x_next.resize(state_dim());
    for (Index a = 0; a < agents(); ++a) {
      const Index k = 4 * a;
      x_next.template segment<2>(k) = x.template segment<2>(k) + dt_ * x.template segment<2>(k + 2);
      x_next.template segment<2>(k + 2) = x.template segment<2>(k + 2) + dt_ * acc.col(a);
    }
  }

  /// A = ∂x_next/∂x (state_dim × state_dim), B = ∂x_next/∂u (state_dim × control_dim).
  void jacobians(const State& x, const Control& u, StateJacobian& a, ControlJacobian& b) const {
    check_sizes(x, u);
    a.setZero(state_dim(), state_dim());
    b.setZero(state_dim(), control_dim());
    for (Index i = 0; i < agents(); ++i) {
      const Index k = 4 * i;
      a.template block<2, 2>(k, k).diagonal().setOnes();
      a.template block<2, 2>(k, k + 2).diagonal().setConstant(dt_);
      a.template block<2, 2>(k + 2, k + 2).diagonal().setConstant(Scalar(1) - dt_ * friction(i));
    }
    const Vec2 centre = center(x);
    for (Index d = 0; d < drivers_; ++d) {
      const Vec2 r = position(x, d) - centre;
      const Mat2 gain = dt_ * control_gain(u, d);
      a.template block<2, 2>(4 * d + 2, 4 * d) += gain;
      for (Index e = drivers_; e < agents(); ++e) {
        a.template block<2, 2>(4 * d + 2, 4 * e) -= center_weight_ * gain;
      }
      b.template block<2, 1>(4 * d + 2, 2 * d) = dt_ * r;
      b.template block<2, 1>(4 * d + 2, 2 * d + 1) = dt_ * perp(r);
    }
    for_each_pair(x, [&](Index i, Index j, Scalar coeff, const Kernel& kernel, bool mutual) {
      const Mat2 jac = (dt_ * coeff) * kernel.jacobian();
      a.template block<2, 2>(4 * i + 2, 4 * i) += jac;
      a.template block<2, 2>(4 * i + 2, 4 * j) -= jac;
      if (mutual) {
        a.template block<2, 2>(4 * j + 2, 4 * j) += jac;
        a.template block<2, 2>(4 * j + 2, 4 * i) -= jac;
      }
    });
  }

  /// *lambda_x = Aᵀ λ (state_dim), *lambda_u = Bᵀ λ (control_dim), without forming A or B:
  /// O((D + E)²) for the pair forces. A null pointer skips that product; `lambda_x` must not
  /// alias `lambda`.
  void vjp(const State& x, const Control& u, const State& lambda, State* lambda_x,
           Control* lambda_u) const {
    check_sizes(x, u);
    detail::require(lambda.size() == state_dim(), "GuidanceByRepulsion: lambda has size ",
                    lambda.size(), ", expected state_dim() = ", state_dim());
    const Vec2 centre = center(x);
    // μ_i = dt λ_{v_i}: the adjoint of agent i's acceleration.
    const auto mu = [&](Index i) -> Vec2 { return dt_ * lambda.template segment<2>(4 * i + 2); };
    if (lambda_u != nullptr) {
      lambda_u->resize(control_dim());
      for (Index d = 0; d < drivers_; ++d) {
        const Vec2 r = position(x, d) - centre;
        const Vec2 m = mu(d);
        (*lambda_u)(2 * d) = r.dot(m);
        (*lambda_u)(2 * d + 1) = perp(r).dot(m);
      }
    }
    if (lambda_x == nullptr) return;
    State& out = *lambda_x;
    out.resize(state_dim());
    for (Index i = 0; i < agents(); ++i) {
      const Index k = 4 * i;
      out.template segment<2>(k) = lambda.template segment<2>(k);
      out.template segment<2>(k + 2) = dt_ * lambda.template segment<2>(k) +
                                       (Scalar(1) - dt_ * friction(i)) *
                                           lambda.template segment<2>(k + 2);
    }
    Vec2 pulled_on_centre = Vec2::Zero();  // Σ_d (∂F_con,d/∂S)ᵀ μ_d, shared by all evaders
    for (Index d = 0; d < drivers_; ++d) {
      const Vec2 g = control_gain(u, d).transpose() * mu(d);
      out.template segment<2>(4 * d) += g;
      pulled_on_centre += g;
    }
    for (Index e = drivers_; e < agents(); ++e) {
      out.template segment<2>(4 * e) -= center_weight_ * pulled_on_centre;
    }
    for_each_pair(x, [&](Index i, Index j, Scalar coeff, const Kernel& kernel, bool mutual) {
      const Vec2 g = coeff * kernel.apply(mutual ? Vec2(mu(i) - mu(j)) : mu(i));
      out.template segment<2>(4 * i) += g;
      out.template segment<2>(4 * j) -= g;
    });
  }

private:
  using Vec2 = Eigen::Matrix<Scalar, 2, 1>;
  using Mat2 = Eigen::Matrix<Scalar, 2, 2>;
  using Kernel = detail::RadialKernel<Scalar>;
  using Accelerations = Eigen::Matrix<Scalar, 2, kAgents>;  ///< p̈ of every agent, 2 × agents

  static Vec2 perp(const Vec2& r) { return Vec2(-r.y(), r.x()); }

  static auto position(const State& x, Index agent) { return x.template segment<2>(4 * agent); }

  [[nodiscard]] Scalar friction(Index agent) const {
    return agent < drivers_ ? driver_friction_ : evader_friction_;
  }

  /// ∂F_con,d/∂r = c_{d,0} I + c_{d,1} R with R the 90° rotation.
  [[nodiscard]] static Mat2 control_gain(const Control& u, Index d) {
    Mat2 m;
    m << u(2 * d), -u(2 * d + 1), u(2 * d + 1), u(2 * d);
    return m;
  }

  [[nodiscard]] Vec2 center(const State& x) const {
    Vec2 s = Vec2::Zero();
    for (Index e = drivers_; e < agents(); ++e) s += position(x, e);
    return center_weight_ * s;
  }

  /// Calls visit(i, j, coeff, K, mutual) once per interacting pair: agent i receives
  /// coeff · K(p_i − p_j), and, if `mutual`, agent j the opposite force.
  template <class Visit>
  void for_each_pair(const State& x, Visit&& visit) const {
    if constexpr (Drivers != 1) {
      for (Index d = 0; d < drivers_; ++d) {
        for (Index k = d + 1; k < drivers_; ++k) {
          const Vec2 r = position(x, d) - position(x, k);
          visit(d, k, spreading_, detail::repulsion_kernel<Scalar>(r, epsilon_), true);
        }
      }
    }
    for (Index e = drivers_; e < agents(); ++e) {
      for (Index d = 0; d < drivers_; ++d) {
        const Vec2 r = position(x, e) - position(x, d);
        visit(e, d, repulsion_, detail::repulsion_kernel<Scalar>(r, epsilon_), false);
      }
    }
    if constexpr (Evaders != 1) {
      for (Index e = drivers_; e < agents(); ++e) {
        for (Index i = e + 1; i < agents(); ++i) {
          const Vec2 r = position(x, e) - position(x, i);
          visit(e, i, flocking_,
                detail::flocking_kernel<Scalar>(r, flocking_offset_, flocking_range_), true);
        }
      }
    }
  }

  void accelerations(const State& x, const Control& u, Accelerations& acc) const {
    acc.resize(2, agents());
    for (Index i = 0; i < agents(); ++i) {
      acc.col(i) = -friction(i) * x.template segment<2>(4 * i + 2);
    }
    const Vec2 centre = center(x);
    for (Index d = 0; d < drivers_; ++d) {
      const Vec2 r = position(x, d) - centre;
      acc.col(d) += u(2 * d) * r + u(2 * d + 1) * perp(r);
    }
    for_each_pair(x, [&](Index i, Index j, Scalar coeff, const Kernel& kernel, bool mutual) {
      const Vec2 force = coeff * kernel.value();
      acc.col(i) += force;
      if (mutual) acc.col(j) -= force;
    });
  }

  /// Fixed sizes are checked by the compiler; dynamic ones here, since a mismatch would
  /// otherwise read out of bounds in a Release build.
  void check_sizes(const State& x, const Control& u) const {
    if constexpr (kStateSize == Eigen::Dynamic) {
      detail::require(x.size() == state_dim(), "GuidanceByRepulsion: x has size ", x.size(),
                      ", expected state_dim() = ", state_dim());
      detail::require(u.size() == control_dim(), "GuidanceByRepulsion: u has size ", u.size(),
                      ", expected control_dim() = ", control_dim());
    }
  }

  Index drivers_, evaders_;
  Options options_;
  Scalar dt_{}, epsilon_{}, driver_friction_{}, evader_friction_{}, spreading_{}, repulsion_{};
  Scalar flocking_{}, flocking_offset_{}, flocking_range_{}, center_weight_{};
};

/// Physics loss ℓ(x) = Σ_e ‖p_e‖² / (2E): the mean over evaders and coordinates of p², i.e.
/// ‖p_e‖²/2 averaged over evaders (target at the origin, as hard-coded in the reference).
template <class ScalarT = double, int Drivers = 2, int Evaders = 4>
class GuidanceLoss {
public:
  using Scalar = ScalarT;
  using State = typename GuidanceByRepulsion<Scalar, Drivers, Evaders>::State;

  GuidanceLoss()
    requires(Drivers != Eigen::Dynamic && Evaders != Eigen::Dynamic)
      : drivers_(Drivers), evaders_(Evaders) {}

  /// Agent counts at run time; throws InvalidArgument unless both are ≥ 1.
  GuidanceLoss(Index drivers, Index evaders) : drivers_(drivers), evaders_(evaders) {
    detail::require(drivers >= 1 && evaders >= 1, "GuidanceLoss: drivers = ", drivers,
                    ", evaders = ", evaders, ", expected both >= 1");
  }

  /// Returns ℓ(x) (x: 4(D+E)); if `grad` is not null sets *grad = ∂ℓ/∂x (p_e / E on evader
  /// positions, 0 elsewhere). Throws InvalidArgument on a wrong state size.
  Scalar operator()(const State& x, State* grad) const {
    const Index n = 4 * (drivers_ + evaders_);
    detail::require(x.size() == n, "GuidanceLoss: state size ", x.size(), ", expected ", n);
    const Scalar inv_e = Scalar(1) / static_cast<Scalar>(evaders_);
    if (grad != nullptr) grad->setZero(n);
    Scalar sum(0);
    for (Index e = drivers_; e < drivers_ + evaders_; ++e) {
      const auto p = x.template segment<2>(4 * e);
      sum += p.squaredNorm();
      if (grad != nullptr) grad->template segment<2>(4 * e) = inv_e * p;
    }
    return Scalar(0.5) * inv_e * sum;
  }

private:
  Index drivers_, evaders_;
};

/// Draws `count` initial states of the paper's distribution (state_dim × count, one sample per
/// column; all velocities 0). Per sample, in this order: each driver radius ~ U[3, 4) (uniform
/// in r, not in area) then angle ~ U[0, 2π); the evader group centre radius ~ U[1, 2) then
/// angle; then each evader's offset (x, y) ~ U[−0.5, 0.5)².
template <class Scalar, int Drivers, int Evaders>
[[nodiscard]] Matrix<Scalar> guidance_initial_states(
    const GuidanceByRepulsion<Scalar, Drivers, Evaders>& sim, Rng& rng, Index count) {
  detail::require(count >= 0, "guidance_initial_states: count = ", count, ", expected >= 0");
  constexpr double two_pi = 2.0 * std::numbers::pi;
  Matrix<Scalar> states = Matrix<Scalar>::Zero(sim.state_dim(), count);
  const auto polar = [&](double r_low, double r_high, double& px, double& py) {
    const double radius = rng.uniform(r_low, r_high);
    const double angle = rng.uniform(0.0, two_pi);
    px = radius * std::cos(angle);
    py = radius * std::sin(angle);
  };
  for (Index j = 0; j < count; ++j) {
    double px = 0, py = 0;
    for (Index d = 0; d < sim.drivers(); ++d) {
      polar(3.0, 4.0, px, py);
      states(4 * d, j) = static_cast<Scalar>(px);
      states(4 * d + 1, j) = static_cast<Scalar>(py);
    }
    double cx = 0, cy = 0;
    polar(1.0, 2.0, cx, cy);
    for (Index e = sim.drivers(); e < sim.agents(); ++e) {
      states(4 * e, j) = static_cast<Scalar>(cx + rng.uniform(-0.5, 0.5));
      states(4 * e + 1, j) = static_cast<Scalar>(cy + rng.uniform(-0.5, 0.5));
    }
  }
  return states;
}

}  // namespace sbptt
