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
/// with one evader. `step` and `vjp` are written once on the state's numbers (`step_values`,
/// `vjp_values`) for one sample or, in float with fixed agent counts, a block of 16 samples
/// in SIMD lanes (`step_batch`, `vjp_batch`; the blocks in `guidance_lanes.hpp`). The
/// options, the pair forces and their Jacobians are in `guidance_forces.hpp`, with how two
/// agents on the same spot are handled (finite values, continuous Jacobians); the paper's loss
/// and initial states in `guidance_task.hpp`.
#include <cmath>
#include <type_traits>

#include <Eigen/Core>

#include "sbptt/core/error.hpp"
#include "sbptt/core/types.hpp"
#include "sbptt/sim/guidance_forces.hpp"
#include "sbptt/sim/guidance_lanes.hpp"

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
    AccelerationValues acc(2 * agents());
    x_next.resize(state_dim());
    step_values(x.data(), u.data(), acc.data(), x_next.data());
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
    Vec2 centre;
    center_values(x.data(), centre.x(), centre.y());
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
    for_each_pair(x.data(), [&](Index i, Index j, Scalar coeff, const Kernel& kernel,
                                bool mutual) {
      const Vec2 n(kernel.nx, kernel.ny);
      const Mat2 jac =
          (dt_ * coeff) * (kernel.s * Mat2::Identity() + kernel.w * n * n.transpose());
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
    if (lambda_u != nullptr) lambda_u->resize(control_dim());
    if (lambda_x != nullptr) lambda_x->resize(state_dim());
    vjp_values(x.data(), u.data(), lambda.data(), lambda_x ? lambda_x->data() : nullptr,
               lambda_u ? lambda_u->data() : nullptr);
  }

  /// `step` for every column of x (state_dim × B) and u (control_dim × B) into x_next
  /// (resized to state_dim × B; it may be x itself). Float with fixed agent counts: the
  /// samples run side by side in SIMD lanes (lane_rows.hpp) through the same lines as `step`
  /// (`step_values`); the lanes round a sum of two products as the compiler fuses it
  /// (`sum_of_products`), so the two agree to rounding, not bit for bit. A column's result
  /// does not depend on the other columns.
  void step_batch(const Matrix<Scalar>& x, const Matrix<Scalar>& u, Matrix<Scalar>& x_next) const
    requires(std::is_same_v<Scalar, float> && kAgents != Eigen::Dynamic)
  {
    detail::GuidanceLanes<GuidanceByRepulsion>(*this).step(x, u, x_next);
  }

  /// `vjp` for every column of x (state_dim × B), u (control_dim × B) and lambda (state_dim ×
  /// B): lambda_x (if not null) resized to state_dim × B, lambda_u to control_dim × B. As
  /// `step_batch`: SIMD lanes, equal to `vjp` to rounding.
  void vjp_batch(const Matrix<Scalar>& x, const Matrix<Scalar>& u, const Matrix<Scalar>& lambda,
                 Matrix<Scalar>* lambda_x, Matrix<Scalar>* lambda_u) const
    requires(std::is_same_v<Scalar, float> && kAgents != Eigen::Dynamic)
  {
    detail::GuidanceLanes<GuidanceByRepulsion>(*this).vjp(x, u, lambda, lambda_x, lambda_u);
  }

  /// `vjp_batch` of two adjoints per sample, lambda_1 and lambda_2 (each state_dim × B), in
  /// one call: the two halves of vjp_batch([x x], [u u], [lambda_1 lambda_2]) into lambda_x_k
  /// and lambda_u_k, bit for bit, without forming those matrices. Each pair of outputs is both
  /// null or both set, and every output is a matrix of its own, none of the inputs. The
  /// combined update's two sweeps go through here (bptt/batch_physics.hpp).
  void vjp_batch_pair(const Matrix<Scalar>& x, const Matrix<Scalar>& u,
                      const Matrix<Scalar>& lambda_1, const Matrix<Scalar>& lambda_2,
                      Matrix<Scalar>* lambda_x_1, Matrix<Scalar>* lambda_x_2,
                      Matrix<Scalar>* lambda_u_1, Matrix<Scalar>* lambda_u_2) const
    requires(std::is_same_v<Scalar, float> && kAgents != Eigen::Dynamic)
  {
    detail::GuidanceLanes<GuidanceByRepulsion>(*this).vjp_pair(
        x, u, lambda_1, lambda_2, lambda_x_1, lambda_x_2, lambda_u_1, lambda_u_2);
  }

private:
  using Vec2 = Eigen::Matrix<Scalar, 2, 1>;
  using Mat2 = Eigen::Matrix<Scalar, 2, 2>;
  using Kernel = detail::PairKernel<Scalar>;
  /// p̈ of every agent, x then y: scratch of `step`.
  using AccelerationValues = Eigen::Matrix<Scalar, detail::times_or_dynamic(2, kAgents), 1>;
  // The batch path runs the same private `step_values` and `vjp_values` as `step` and `vjp`.
  friend class detail::GuidanceLanes<GuidanceByRepulsion>;

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

  // The equations of `step` and `vjp` on the numbers of one sample (V = Scalar, pointers into
  // its vectors) or of a block of samples side by side (V = a lane array, one per state row):
  // x, lambda, x_next, lambda_x hold state_dim values, u, lambda_u control_dim, acc 2·agents.

  /// The centre S of the control frame, (cx, cy).
  template <class V>
  void center_values(const V* x, V& cx, V& cy) const {
    cx = x[4 * drivers_];
    cy = x[4 * drivers_ + 1];
    for (Index e = drivers_ + 1; e < agents(); ++e) {
      cx += x[4 * e];
      cy += x[4 * e + 1];
    }
    cx *= center_weight_;
    cy *= center_weight_;
  }

  /// Calls visit(i, j, coeff, K, mutual) once per interacting pair: agent i receives
  /// coeff · K(p_i − p_j), and, if `mutual`, agent j the opposite force.
  template <class V, class Visit>
  void for_each_pair(const V* x, Visit&& visit) const {
    auto separation = [&](Index i, Index j, auto&& kernel) {
      return kernel(V(x[4 * i] - x[4 * j]), V(x[4 * i + 1] - x[4 * j + 1]));
    };
    auto repulsion = [&](const V& rx, const V& ry) {
      return detail::repulsion_kernel(rx, ry, epsilon_);
    };
    auto flocking = [&](const V& rx, const V& ry) {
      return detail::flocking_kernel(rx, ry, flocking_offset_, flocking_range_);
    };
    if constexpr (Drivers != 1) {
      for (Index d = 0; d < drivers_; ++d)
        for (Index k = d + 1; k < drivers_; ++k)
          visit(d, k, spreading_, separation(d, k, repulsion), true);
    }
    for (Index e = drivers_; e < agents(); ++e)
      for (Index d = 0; d < drivers_; ++d)
        visit(e, d, repulsion_, separation(e, d, repulsion), false);
    if constexpr (Evaders != 1) {
      for (Index e = drivers_; e < agents(); ++e)
        for (Index i = e + 1; i < agents(); ++i)
          visit(e, i, flocking_, separation(e, i, flocking), true);
    }
  }

  /// p̈ of every agent into acc (x then y per agent).
  template <class V>
  void accelerations(const V* x, const V* u, V* acc) const {
    for (Index i = 0; i < agents(); ++i) {
      acc[2 * i] = -friction(i) * x[4 * i + 2];
      acc[2 * i + 1] = -friction(i) * x[4 * i + 3];
    }
    V cx, cy;
    center_values(x, cx, cy);
    for (Index d = 0; d < drivers_; ++d) {  // F_con,d = c_{d,0} r + c_{d,1} r⊥, r⊥ = (−r_y, r_x)
      const V rx = x[4 * d] - cx, ry = x[4 * d + 1] - cy;
      acc[2 * d] += detail::sum_of_products<V>(u[2 * d], rx, u[2 * d + 1], V(-ry));
      acc[2 * d + 1] += detail::sum_of_products<V>(u[2 * d], ry, u[2 * d + 1], rx);
    }
    for_each_pair(x, [&](Index i, Index j, Scalar coeff, const detail::PairKernel<V>& k,
                         bool mutual) {
      const V fx = coeff * V(k.s * k.rx), fy = coeff * V(k.s * k.ry);
      acc[2 * i] += fx;
      acc[2 * i + 1] += fy;
      if (mutual) {
        acc[2 * j] -= fx;
        acc[2 * j + 1] -= fy;
      }
    });
  }

  /// Explicit Euler: p' = p + dt v, v' = v + dt p̈. x_next may be x.
  template <class V>
  void step_values(const V* x, const V* u, V* acc, V* x_next) const {
    accelerations(x, u, acc);
    for (Index a = 0; a < agents(); ++a) {
      for (Index c = 0; c < 2; ++c) {
        const Index k = 4 * a + c;
        const V velocity = x[k + 2];
        x_next[k] = x[k] + dt_ * velocity;
        x_next[k + 2] = velocity + dt_ * acc[2 * a + c];
      }
    }
  }

  /// Aᵀλ into lambda_x and Bᵀλ into lambda_u (either may be null).
  template <class V>
  void vjp_values(const V* x, const V* u, const V* lambda, V* lambda_x, V* lambda_u) const {
    V cx, cy;
    center_values(x, cx, cy);
    // μ_i = dt λ_{v_i}: the adjoint of agent i's acceleration.
    auto mu = [&](Index i, Index c) -> V { return dt_ * lambda[4 * i + 2 + c]; };
    if (lambda_u != nullptr) {
      for (Index d = 0; d < drivers_; ++d) {  // r·μ and r⊥·μ
        const V rx = x[4 * d] - cx, ry = x[4 * d + 1] - cy;
        const V m0 = mu(d, 0), m1 = mu(d, 1);
        lambda_u[2 * d] = detail::sum_of_products<V>(rx, m0, ry, m1);
        lambda_u[2 * d + 1] = detail::sum_of_products<V>(V(-ry), m0, rx, m1);
      }
    }
    if (lambda_x == nullptr) return;
    V* out = lambda_x;
    for (Index i = 0; i < agents(); ++i) {
      for (Index c = 0; c < 2; ++c) {
        const Index k = 4 * i + c;
        out[k] = lambda[k];
        const Scalar kept = Scalar(1) - dt_ * friction(i);
        out[k + 2] = detail::sum_of_products<V>(dt_, lambda[k], kept, lambda[k + 2]);
      }
    }
    // Σ_d (∂F_con,d/∂S)ᵀ μ_d, shared by all evaders; (∂F_con,d/∂r)ᵀ = [[c0, c1], [−c1, c0]].
    V pulled_x = zero<V>(), pulled_y = zero<V>();
    for (Index d = 0; d < drivers_; ++d) {
      const V m0 = mu(d, 0), m1 = mu(d, 1);
      const V gx = detail::sum_of_products<V>(u[2 * d], m0, u[2 * d + 1], m1);
      const V gy = detail::sum_of_products<V>(V(-u[2 * d + 1]), m0, u[2 * d], m1);
      out[4 * d] += gx;
      out[4 * d + 1] += gy;
      pulled_x += gx;
      pulled_y += gy;
    }
    for (Index e = drivers_; e < agents(); ++e) {
      out[4 * e] -= center_weight_ * pulled_x;
      out[4 * e + 1] -= center_weight_ * pulled_y;
    }
    for_each_pair(x, [&](Index i, Index j, Scalar coeff, const detail::PairKernel<V>& k,
                         bool mutual) {
      const V ax = mutual ? V(mu(i, 0) - mu(j, 0)) : mu(i, 0);
      const V ay = mutual ? V(mu(i, 1) - mu(j, 1)) : mu(i, 1);
      V gx, gy;
      k.apply(ax, ay, gx, gy);
      out[4 * i] += coeff * gx;
      out[4 * i + 1] += coeff * gy;
      out[4 * j] -= coeff * gx;
      out[4 * j + 1] -= coeff * gy;
    });
  }

  /// 0 as one number or as a lane array.
  template <class V>
  [[nodiscard]] static V zero() {
    if constexpr (std::is_base_of_v<Eigen::ArrayBase<V>, V>) {
      return V::Zero();
    } else {
      return V(0);
    }
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

}  // namespace sbptt

// The task helpers lived here before guidance_task.hpp: code that includes only this compiles.
#include "sbptt/sim/guidance_task.hpp"  // IWYU pragma: export
