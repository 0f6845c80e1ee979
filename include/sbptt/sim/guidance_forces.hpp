#pragma once
/// \file The forces of the guidance-by-repulsion scene (equations in guidance_by_repulsion.hpp):
/// their constants and switches (`GuidanceOptions`), and the pair kernels with their Jacobians.
///
/// Every pair force in the scene has the form K(r) = s(ρ) r with ρ = ‖r‖, so
///
///     ∂K/∂r = s(ρ) I + s'(ρ) ρ n nᵀ,      n = r / ρ  (the derivative of ‖r‖).
///
/// ‖r‖ is not differentiable at r = 0 (two agents on the same spot). We take n = 0 there. That
/// is not an arbitrary choice: the ρ-dependence of K enters multiplied by r, so K is C¹ at 0
/// and its Jacobian tends to s(0) I from every direction; n = 0 gives exactly that limit, and
/// nothing is divided by ρ, so no NaN can appear (and no 1/ρ blows up for ρ ≈ 1e-6).
#include <cmath>
#include <utility>

#include <Eigen/Core>

#include "sbptt/core/error.hpp"
#include "sbptt/core/types.hpp"

namespace sbptt {

/// What the drivers' control frame is centred on.
enum class GuidanceCenter {
  Sum,       ///< S = Σ_e p_e, as the reference computes it (E times the centroid)
  Centroid,  ///< S = mean_e p_e, what "centre" means physically
};

/// Sign of the evader–evader flocking force.
enum class FlockingSign {
  AsCoded,     ///< the reference: short-range attraction, repulsion beyond ‖r‖ ≈ 0.4
  AsIntended,  ///< the reference's comment: short-range repulsion, attraction beyond
};

/// Switches between the reference's behaviour (defaults) and the physically intended one.
struct GuidancePhysics {
  GuidanceCenter center = GuidanceCenter::Sum;
  FlockingSign flocking = FlockingSign::AsCoded;
};

/// Horizon and constants of `GuidanceByRepulsion`. Defaults are the paper's (§4).
struct GuidanceOptions {
  double horizon = 4.0;           ///< T (> 0)
  Index steps = 60;               ///< Nt (> 0); dt = T / Nt
  double epsilon = 0.1;           ///< ε in dist(r) = ε + ‖r‖ (> 0: keeps 1/dist² finite)
  double driver_friction = 1.0;   ///< γ_D
  double evader_friction = 4.0;   ///< γ_E
  double spreading_gain = 0.2;    ///< κ_S, driver–driver repulsion
  double repulsion_gain = 15.0;   ///< κ_R, driver-on-evader repulsion
  double flocking_gain = 0.2;     ///< κ_F
  double flocking_offset = 0.1;   ///< δ₀ in δ = δ₀ + ‖r‖ (> 0)
  double flocking_range = 0.5;    ///< ρ_F, f(δ) = (ρ_F/δ − 1)/δ changes sign at δ = ρ_F
  GuidancePhysics physical{};     ///< reference quirks (faithful by default)
};

namespace detail {

/// Throws InvalidArgument naming the first bad option and what was expected.
inline void validate_guidance_options(const GuidanceOptions& options) {
  const char* who = "GuidanceByRepulsion: ";
  require(std::isfinite(options.horizon) && options.horizon > 0, who, "horizon = ",
          options.horizon, ", expected a finite T > 0");
  require(options.steps >= 1, who, "steps = ", options.steps, ", expected >= 1");
  // Both offsets keep the pair forces finite when two agents meet.
  require(std::isfinite(options.epsilon) && options.epsilon > 0, who, "epsilon = ",
          options.epsilon, ", expected a finite value > 0");
  require(std::isfinite(options.flocking_offset) && options.flocking_offset > 0, who,
          "flocking_offset = ", options.flocking_offset, ", expected a finite value > 0");
  const std::pair<const char*, double> finite[] = {
      {"driver_friction", options.driver_friction}, {"evader_friction", options.evader_friction},
      {"spreading_gain", options.spreading_gain},   {"repulsion_gain", options.repulsion_gain},
      {"flocking_gain", options.flocking_gain},     {"flocking_range", options.flocking_range}};
  for (const auto& [name, value] : finite) {
    require(std::isfinite(value), who, name, " = ", value, ", expected a finite number");
  }
  const auto center = options.physical.center;
  require(center == GuidanceCenter::Sum || center == GuidanceCenter::Centroid, who,
          "physical.center = ", static_cast<int>(center), ", expected Sum or Centroid");
  const auto flocking = options.physical.flocking;
  require(flocking == FlockingSign::AsCoded || flocking == FlockingSign::AsIntended, who,
          "physical.flocking = ", static_cast<int>(flocking), ", expected AsCoded or AsIntended");
}

/// K(r) = s r and ∂K/∂r = s I + w n nᵀ (symmetric) for one agent pair.
template <class Scalar>
struct RadialKernel {
  using Vec2 = Eigen::Matrix<Scalar, 2, 1>;
  using Mat2 = Eigen::Matrix<Scalar, 2, 2>;

  Scalar s{};  ///< the radial profile s(ρ)
  Scalar w{};  ///< s'(ρ) ρ
  Vec2 r;      ///< the separation the kernel was evaluated at
  Vec2 n;      ///< r / ρ, or 0 at ρ = 0

  [[nodiscard]] Vec2 value() const { return s * r; }
  [[nodiscard]] Mat2 jacobian() const { return s * Mat2::Identity() + w * n * n.transpose(); }
  /// (∂K/∂r)ᵀ μ = (∂K/∂r) μ, the Jacobian being symmetric.
  [[nodiscard]] Vec2 apply(const Vec2& mu) const { return s * mu + w * n * n.dot(mu); }
};

/// Fills ρ and n for separation r (n = 0 at coincidence, see the file comment).
template <class Scalar>
void radial_frame(const Eigen::Matrix<Scalar, 2, 1>& r, Scalar& rho,
                  Eigen::Matrix<Scalar, 2, 1>& n) {
  using std::sqrt;
  rho = sqrt(r.squaredNorm());
  if (rho > Scalar(0)) {
    n = r / rho;
  } else {
    n.setZero();
  }
}

/// Inverse-square repulsion r / (ε + ‖r‖)², i.e. s = (ε + ρ)⁻², s' = −2 (ε + ρ)⁻³.
template <class Scalar>
[[nodiscard]] RadialKernel<Scalar> repulsion_kernel(const Eigen::Matrix<Scalar, 2, 1>& r,
                                                    Scalar epsilon) {
  RadialKernel<Scalar> k;
  Scalar rho;
  radial_frame(r, rho, k.n);
  const Scalar q = Scalar(1) / (epsilon + rho);
  k.s = q * q;
  k.w = Scalar(-2) * q * q * q * rho;
  k.r = r;
  return k;
}

/// Flocking profile f(d) r with d = offset + ‖r‖ and f(d) = (range/d − 1)/d = range/d² − 1/d,
/// so s = f(d), s' = f'(d) = −2 range/d³ + 1/d². f changes sign at d = range.
template <class Scalar>
[[nodiscard]] RadialKernel<Scalar> flocking_kernel(const Eigen::Matrix<Scalar, 2, 1>& r,
                                                   Scalar offset, Scalar range) {
  RadialKernel<Scalar> k;
  Scalar rho;
  radial_frame(r, rho, k.n);
  const Scalar q = Scalar(1) / (offset + rho);
  k.s = (range * q - Scalar(1)) * q;
  k.w = (Scalar(-2) * range * q + Scalar(1)) * q * q * rho;
  k.r = r;
  return k;
}

}  // namespace detail
}  // namespace sbptt
