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
/// no result is divided by ρ, so no NaN can appear (and no 1/ρ blows up for ρ ≈ 1e-6). A
/// block of samples in lanes does divide by ρ in every lane and then selects n = 0 where
/// ρ = 0: the 0/0 of such a lane is computed and dropped (it would trap only if a program
/// enabled floating-point exceptions).
#include <cmath>
#include <type_traits>
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

/// a·b + c·d rounded in one fixed order. With hardware FMA the compiler fuses a sum of two
/// products into a multiply-add of either one, and chose differently in different inlined
/// copies of the same line (a fixed and a dynamic agent count gave results one rounding apart),
/// so a number gets fma(a, b, c·d) explicitly. A lane array keeps the compiler's choice: its
/// lanes agree with the per-sample step to rounding anyway.
template <class V, class A, class B, class C, class D>
[[nodiscard]] V sum_of_products(const A& a, const B& b, const C& c, const D& d) {
#if defined(FP_FAST_FMA) || defined(FP_FAST_FMAF) || defined(__FMA__)
  if constexpr (std::is_floating_point_v<V>) return std::fma(a, b, c * d);
#endif
  return a * b + c * d;
}

/// One agent pair: K(r) = s r and ∂K/∂r = s I + w n nᵀ (symmetric). `V` is one number (a
/// sample) or a lane array (a block of samples side by side, `step_batch`).
template <class V>
struct PairKernel {
  V rx, ry;  ///< the separation r the kernel was evaluated at
  V nx, ny;  ///< r / ρ, or 0 at ρ = 0
  V s;       ///< the radial profile s(ρ)
  V w;       ///< s'(ρ) ρ

  /// (∂K/∂r)ᵀ (ax, ay) = (∂K/∂r)(ax, ay), the Jacobian being symmetric, into (gx, gy).
  void apply(const V& ax, const V& ay, V& gx, V& gy) const {
    const V along = sum_of_products<V>(nx, ax, ny, ay);
    gx = sum_of_products<V>(s, ax, V(w * nx), along);
    gy = sum_of_products<V>(s, ay, V(w * ny), along);
  }
};

/// r, n and ρ for the separation (rx, ry) (n = 0 at coincidence, see the file comment).
template <class V>
[[nodiscard]] PairKernel<V> pair_frame(const V& rx, const V& ry, V& rho) {
  using std::sqrt;
  rho = sqrt(rx * rx + ry * ry);
  PairKernel<V> k;
  k.rx = rx;
  k.ry = ry;
  if constexpr (std::is_base_of_v<Eigen::ArrayBase<V>, V>) {  // lanes: a select per lane
    const auto apart = rho > typename V::Scalar(0);
    k.nx = apart.select(rx / rho, V::Zero());
    k.ny = apart.select(ry / rho, V::Zero());
  } else if (rho > V(0)) {
    k.nx = rx / rho;
    k.ny = ry / rho;
  } else {
    k.nx = V(0);
    k.ny = V(0);
  }
  return k;
}

/// Inverse-square repulsion r / (ε + ‖r‖)², i.e. s = (ε + ρ)⁻², s' = −2 (ε + ρ)⁻³.
template <class V, class Scalar>
[[nodiscard]] PairKernel<V> repulsion_kernel(const V& rx, const V& ry, Scalar epsilon) {
  V rho;
  PairKernel<V> k = pair_frame(rx, ry, rho);
  const V q = Scalar(1) / (epsilon + rho);
  k.s = q * q;
  k.w = Scalar(-2) * q * q * q * rho;
  return k;
}

/// Flocking profile f(d) r with d = offset + ‖r‖ and f(d) = (range/d − 1)/d = range/d² − 1/d,
/// so s = f(d), s' = f'(d) = −2 range/d³ + 1/d². f changes sign at d = range.
template <class V, class Scalar>
[[nodiscard]] PairKernel<V> flocking_kernel(const V& rx, const V& ry, Scalar offset,
                                            Scalar range) {
  V rho;
  PairKernel<V> k = pair_frame(rx, ry, rho);
  const V q = Scalar(1) / (offset + rho);
  k.s = (range * q - Scalar(1)) * q;
  k.w = (Scalar(-2) * range * q + Scalar(1)) * q * q * rho;
  return k;
}

}  // namespace detail
}  // namespace sbptt
