#pragma once
/// \file The serial n-link pendulum on a cart (links hinged end to end: the double and triple
/// inverted pendulum), from its Lagrangian; a truly coupled, chaotic cart pole.
///
/// Coordinates q = (x, θ_1, …, θ_n): cart position, and each link's absolute angle from the
/// upward vertical (θ = 0 upright, as in `CartPole`). Link i is a uniform rod of mass m_i and
/// length L_i, centre of mass c_i = L_i / 2 from its lower joint, inertia I_i = m_i L_i² / 12
/// about its centre; link 1 is hinged on the cart (mass m_c), link i + 1 on the upper end of
/// link i. The centre of link i is at
///
///     (x + Σ_{k<i} L_k sin θ_k + c_i sin θ_i,   Σ_{k<i} L_k cos θ_k + c_i cos θ_i).
///
/// With h_k = m_k c_k + L_k Σ_{i>k} m_i (the first moment of everything link k carries),
/// g_kk = m_k c_k² + L_k² Σ_{i>k} m_i and g_jk = g_kj = L_j h_k for j < k, the Lagrangian
/// L = ½ q̇ᵀ M(q) q̇ − V(q) has
///
///     M_00 = m_c + Σ_i m_i,   M_0k = h_k cos θ_k,   M_jk = g_jk cos(θ_j − θ_k) + δ_jk I_k,
///     V    = g Σ_k h_k cos θ_k,
///
/// and the Euler–Lagrange equations M(q) q̈ = τ − c(q, q̇) − ∂V/∂q, τ = (F, 0, …, 0), read
///
///     row 0:  M_00 ẍ + Σ_k h_k cos θ_k θ̈_k = F + Σ_k h_k sin θ_k θ̇_k²
///     row j:  h_j cos θ_j ẍ + Σ_k M_jk θ̈_k = g h_j sin θ_j − Σ_k g_jk sin(θ_j − θ_k) θ̇_k²
///
/// (the θ̇² sums are the centrifugal and Coriolis terms c(q, q̇)). The energy
/// E = ½ q̇ᵀ M q̇ + V and the horizontal momentum p = (M q̇)_0 are conserved when F = 0 (no
/// friction anywhere); with a force, dE/dt = F ẋ and dp/dt = F. One link is the physical cart
/// pole (`CartPoleModel::Physical` with one pole): ẍ and θ̈ agree to round-off.
///
/// State layout (size 2 + 2n, as `CartPole`'s, so its loss, initial states and states files
/// apply unchanged): x, ẋ, θ_1, θ̇_1, …, θ_n, θ̇_n. Control: the force F on the cart (size 1).
/// Time stepping: any integrator of sim/integrators.hpp through `Integrated`; `CartChain`
/// defaults to semi-implicit Euler, the cart pole's (ẋ' = ẋ + dt ẍ, x' = x + dt ẋ', per
/// coordinate), and its Jacobians are automatic (Eigen AutoDiff through the (n + 1) × (n + 1)
/// LDLᵀ solve).
///
/// Defaults: every link is the paper's pole (m = 0.1, L = 1), the cart is the physical cart
/// pole's (m_c = 1.0), g = 9.8.
#include <array>
#include <cmath>

#include <Eigen/Cholesky>
#include <Eigen/Core>

#include "sbptt/core/error.hpp"
#include "sbptt/core/types.hpp"
#include "sbptt/sim/autodiff.hpp"
#include "sbptt/sim/integrators.hpp"

namespace sbptt {

/// Physical constants of the cart chain (every link alike). Defaults: see the file comment.
struct CartChainOptions {
  double gravity = 9.8;     ///< g (≥ 0)
  double cart_mass = 1.0;   ///< m_c (> 0)
  double link_mass = 0.1;   ///< m_i (> 0)
  double link_length = 1.0; ///< L_i (> 0)
};

/// The continuous dynamics q̈ = a(q, q̇, F) of `Links` links on a cart, for `Integrated`.
template <int Links>
class CartChainModel {
  static_assert(Links >= 1, "CartChainModel: at least one link");

public:
  static constexpr int kLinks = Links;
  static constexpr int kStateSize = 2 + 2 * Links, kControlSize = 1;
  static constexpr StateLayout kLayout = StateLayout::Interleaved;
  template <class T>
  using State = ColumnOf<T, kStateSize>;
  template <class T>
  using MassMatrix = Eigen::Matrix<T, Links + 1, Links + 1>;

  explicit CartChainModel(const CartChainOptions& options = {}) : options_(options) {
    const auto& o = options;
    detail::require(std::isfinite(o.gravity) && o.gravity >= 0, "CartChain: gravity = ",
                    o.gravity, "; expected a finite number >= 0");
    detail::require(std::isfinite(o.cart_mass) && o.cart_mass > 0, "CartChain: cart mass = ",
                    o.cart_mass, "; expected a finite number > 0");
    detail::require(std::isfinite(o.link_mass) && o.link_mass > 0, "CartChain: link mass = ",
                    o.link_mass, "; expected a finite number > 0");
    detail::require(std::isfinite(o.link_length) && o.link_length > 0,
                    "CartChain: link length = ", o.link_length, "; expected a finite number > 0");
    const double m = o.link_mass, length = o.link_length, c = length / 2;
    for (int k = 0; k < Links; ++k) {
      const double carried = m * (Links - 1 - k);  // Σ_{i>k} m_i
      moment_[idx(k)] = m * c + length * carried;
      self_[idx(k)] = m * c * c + length * length * carried;
    }
    inertia_ = m * length * length / 12;
    total_mass_ = o.cart_mass + Links * m;
  }

  [[nodiscard]] const CartChainOptions& options() const { return options_; }

  /// M(q) ((n + 1) × (n + 1), symmetric positive definite) at the state x (2 + 2n).
  template <class T>
  [[nodiscard]] MassMatrix<T> mass_matrix(const State<T>& x) const {
    using std::cos;
    MassMatrix<T> mass;
    mass(0, 0) = constant<T>(total_mass_);
    for (int j = 0; j < Links; ++j) {
      mass(0, j + 1) = mass(j + 1, 0) = constant<T>(moment_[idx(j)]) * cos(angle(x, j));
      for (int k = j; k < Links; ++k) {
        const T value = constant<T>(coupling(j, k)) * cos(angle(x, j) - angle(x, k));
        mass(j + 1, k + 1) = mass(k + 1, j + 1) = value;
      }
      mass(j + 1, j + 1) += constant<T>(inertia_);
    }
    return mass;
  }

  /// q̈ = (ẍ, θ̈_1, …, θ̈_n) from x (2 + 2n) and the force u (1): the equations of the file
  /// comment, solved by LDLᵀ.
  template <class T>
  void acceleration(const State<T>& x, const ColumnOf<T, 1>& u,
                    ColumnOf<T, Links + 1>& a) const {
    using std::sin;
    ColumnOf<T, Links + 1> forces;
    forces(0) = u(0);
    for (int k = 0; k < Links; ++k) {
      const T spin = rate(x, k) * rate(x, k);
      forces(0) += constant<T>(moment_[idx(k)]) * sin(angle(x, k)) * spin;
    }
    for (int j = 0; j < Links; ++j) {
      T row = constant<T>(options_.gravity * moment_[idx(j)]) * sin(angle(x, j));
      for (int k = 0; k < Links; ++k) {
        if (k == j) continue;
        row -= constant<T>(coupling(j, k)) * sin(angle(x, j) - angle(x, k)) * rate(x, k) *
               rate(x, k);
      }
      forces(j + 1) = row;
    }
    a = mass_matrix(x).ldlt().solve(forces);
  }

  /// E = ½ q̇ᵀ M q̇ + g Σ_k h_k cos θ_k at the state x (2 + 2n).
  template <class T>
  [[nodiscard]] T energy(const State<T>& x) const {
    using std::cos;
    const ColumnOf<T, Links + 1> velocity = velocities(x);
    T potential(0);
    for (int k = 0; k < Links; ++k)
      potential += constant<T>(options_.gravity * moment_[idx(k)]) * cos(angle(x, k));
    return constant<T>(0.5) * velocity.dot(mass_matrix(x) * velocity) + potential;
  }

  /// The horizontal momentum p = (M q̇)_0 at the state x (2 + 2n).
  template <class T>
  [[nodiscard]] T horizontal_momentum(const State<T>& x) const {
    return mass_matrix(x).row(0).dot(velocities(x));
  }

private:
  template <class T>
  static T angle(const State<T>& x, int k) {
    return x(2 + 2 * k);
  }
  template <class T>
  static T rate(const State<T>& x, int k) {
    return x(3 + 2 * k);
  }
  template <class T>
  static ColumnOf<T, Links + 1> velocities(const State<T>& x) {
    ColumnOf<T, Links + 1> v;
    for (int i = 0; i <= Links; ++i) v(i) = x(2 * i + 1);
    return v;
  }
  static std::size_t idx(int k) { return static_cast<std::size_t>(k); }
  /// g_jk of the file comment.
  [[nodiscard]] double coupling(int j, int k) const {
    if (j == k) return self_[idx(j)];
    return j < k ? options_.link_length * moment_[idx(k)] : options_.link_length * moment_[idx(j)];
  }

  CartChainOptions options_;
  std::array<double, Links> moment_{};  ///< h_k
  std::array<double, Links> self_{};    ///< g_kk
  double inertia_ = 0, total_mass_ = 0;
};

/// The cart chain as a `Simulator`: `CartChainModel<Links>` stepped by `Method` in `Scalar`.
template <class Scalar = double, int Links = 2, class Method = SemiImplicitEuler>
using CartChain = Integrated<CartChainModel<Links>, Method, Scalar>;

}  // namespace sbptt
