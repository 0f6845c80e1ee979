#pragma once
/// \file Quantum state control: the 1-D Schrödinger equation with a controlled linear potential
/// (paper §6), stepped by Crank–Nicolson with an O(Nx) tridiagonal solve.
///
/// Equation (ħ = 1, 2m = 1) on 0 < x < L, ψ(0) = ψ(L) = 0 (infinite well):
///
///     i ∂ψ/∂t = −∂²ψ/∂x² + u(t)·x·ψ
///
/// Space: Nx interior points, dx = L/(Nx+1), x_j = j·dx (j = 1..Nx), 3-point Laplacian:
///
///     H(u) = H₀ + u·X,   (H₀)_jj = 2/dx²,  (H₀)_{j,j±1} = −1/dx²,  X = diag(x_j)
///
/// Time, with h = dt/2:
///
///     U₁ ψ' = U₂ ψ,   U₁ = I + i h H(u),   U₂ = I − i h H(u) = U₁ᴴ   (H is real symmetric)
///
/// M = U₁⁻¹U₂ is the Cayley transform of the Hermitian hH, hence unitary for every u: the norm
/// is kept exactly, and in the real layout A = ∂ψ'/∂ψ is orthogonal.
///
/// State layout (docs/formats.md): real, size 2·Nx, (Re ψ_1, Im ψ_1, Re ψ_2, Im ψ_2, …), the memory
/// layout of a complex vector. Control: u, a 1-vector.
///
/// Derivatives. A complex-linear map m acts on one (Re, Im) pair as the 2×2 block
/// [Re m, −Im m; Im m, Re m]; its transpose is the block of conj(m). So the real transpose of a
/// complex-linear M is its conjugate transpose Mᴴ, not Mᵀ.
///
///     A   = real form of M = U₁⁻¹U₂                       (Nx solves, one per column)
///     B   = ∂ψ'/∂u = −U₁⁻¹ (i h X) (ψ' + ψ)     (∂_u of U₁ψ' = U₂ψ, with ∂_u U₁ = ihX = −∂_u U₂)
///     ψ' + ψ = 2 U₁⁻¹ ψ                                   (U₁ψ' + U₁ψ = U₂ψ + U₁ψ = 2ψ)
///     Aᵀλ = Mᴴλ = U₂ᴴ U₁⁻ᴴ λ = U₁ μ,   μ = U₁⁻ᴴ λ          (one adjoint solve, U₂ᴴ = U₁)
///     Bᵀλ = Re(bᴴλ) = Re(i h (ψ'+ψ)ᴴ X μ) = −h Σ_j x_j Im(conj(ψ'_j + ψ_j) μ_j)   (reuses μ)
///
/// vjp costs one factorisation of U₁, the adjoint solve, one tridiagonal product and, for Bᵀλ
/// only, one forward solve: O(Nx), never forming A.
#include <algorithm>
#include <cmath>
#include <complex>
#include <numbers>
#include <type_traits>

#include "sbptt/core/concepts.hpp"
#include "sbptt/core/error.hpp"
#include "sbptt/core/rng.hpp"
#include "sbptt/sim/schrodinger_lanes.hpp"
#include "sbptt/sim/tridiagonal.hpp"

namespace sbptt {

/// Time step, horizon and well width of `Schrodinger1D` (defaults: the paper's §6 settings).
template <class Scalar = double>
struct SchrodingerOptions {
  Scalar dt = Scalar(0.0625);  ///< time step (paper: T / Nt = 8 / 128)
  Index steps = 128;           ///< episode length m used by training (paper: Nt = 128)
  Scalar length = Scalar(2);   ///< well width L; the walls are at x = 0 and x = L
};

namespace detail {

/// |⟨φ, ψ⟩|² for interleaved complex vectors φ, ψ (2n); if `grad` is not null it is set to
/// ∂F/∂ψ in the same layout (2n), i.e. the pairs of 2·z·φ with z = ⟨φ, ψ⟩ = Σ conj(φ_j) ψ_j.
template <class State>
[[nodiscard]] typename State::Scalar interleaved_fidelity(const State& phi, const State& psi,
                                                          State* grad) {
  using Scalar = typename State::Scalar;
  require(phi.size() == psi.size() && phi.size() % 2 == 0, "fidelity: sizes ", phi.size(),
          " and ", psi.size(), "; expected two equal, even sizes");
  Scalar zr = 0, zi = 0;
  for (Index k = 0; k < phi.size(); k += 2) {
    zr += phi(k) * psi(k) + phi(k + 1) * psi(k + 1);
    zi += phi(k) * psi(k + 1) - phi(k + 1) * psi(k);
  }
  if (grad) {
    grad->resize(psi.size());
    for (Index k = 0; k < phi.size(); k += 2) {
      (*grad)(k) = Scalar(2) * (zr * phi(k) - zi * phi(k + 1));
      (*grad)(k + 1) = Scalar(2) * (zr * phi(k + 1) + zi * phi(k));
    }
  }
  return zr * zr + zi * zi;
}

}  // namespace detail

/// The controlled 1-D Schrödinger equation on `Nx` interior grid points (see the file comment).
/// `Nx = Eigen::Dynamic` takes the grid size as a constructor argument. Immutable, thread-safe.
template <class ScalarT = double, int Nx = 32>
class Schrodinger1D {
  static_assert(std::is_floating_point_v<ScalarT>, "Schrodinger1D: Scalar must be a real type");
  static_assert(Nx == Eigen::Dynamic || Nx >= 1, "Schrodinger1D: Nx must be >= 1 or Dynamic");
  static constexpr int kStateSize = Nx == Eigen::Dynamic ? Eigen::Dynamic : 2 * Nx;
  // The batched step keeps a few blocks of 64 bytes per grid point on the stack (about 225 KiB
  // at Nx = 256: `vjp_batch`'s fields, `vjp`'s and a block's rows on their way in or out), so
  // it needs a fixed Nx, and a bounded one.
  static constexpr bool kLanesInStack = Nx != Eigen::Dynamic && Nx <= 256;

public:
  using Scalar = ScalarT;
  using Complex = std::complex<Scalar>;
  using Options = SchrodingerOptions<Scalar>;
  using State = Eigen::Matrix<Scalar, kStateSize, 1>;  ///< 2Nx, interleaved Re/Im
  using Control = Eigen::Matrix<Scalar, 1, 1>;         ///< the field strength u
  /// Dense 2Nx × 2Nx, always heap-backed: at Nx = 32 it is 32 KiB and Eigen refuses fixed-size
  /// objects above 128 KiB, and jacobians() is not on the O(Nx) path anyway.
  using StateJacobian = Matrix<Scalar>;
  using ControlJacobian = Eigen::Matrix<Scalar, kStateSize, 1>;  ///< 2Nx × 1
  using ComplexVector = Eigen::Matrix<Complex, Nx, 1>;           ///< Nx, ψ_j
  using Grid = Eigen::Matrix<Scalar, Nx, 1>;                     ///< Nx, x_j

  /// Fixed grid size: the paper's scene with `options`.
  explicit Schrodinger1D(const Options& options = {})
    requires(Nx != Eigen::Dynamic)
      : Schrodinger1D(Index{Nx}, options) {}

  /// `nx` interior points (must equal Nx unless Nx is Dynamic).
  explicit Schrodinger1D(Index nx, const Options& options = {})
      : nx_(nx), dt_(options.dt), steps_(options.steps), length_(options.length) {
    if constexpr (Nx == Eigen::Dynamic) {
      detail::require(nx_ >= 1, "Schrodinger1D: nx = ", nx_, "; expected at least 1");
    } else {
      detail::require(nx_ == Nx, "Schrodinger1D: nx = ", nx_, "; expected the template's Nx = ",
                      Nx);
    }
    detail::require(std::isfinite(dt_) && dt_ > 0, "Schrodinger1D: dt = ", dt_,
                    "; expected a finite number > 0");
    detail::require(steps_ >= 1, "Schrodinger1D: steps = ", steps_, "; expected >= 1");
    detail::require(std::isfinite(length_) && length_ > 0, "Schrodinger1D: length = ", length_,
                    "; expected a finite number > 0");
    dx_ = length_ / static_cast<Scalar>(nx_ + 1);
    inv_dx2_ = Scalar(1) / (dx_ * dx_);
  }

  [[nodiscard]] Index state_dim() const { return 2 * grid_size(); }
  [[nodiscard]] Index control_dim() const { return 1; }
  [[nodiscard]] Scalar dt() const { return dt_; }
  /// Nx (a compile-time constant for fixed Nx, so the loops below see the true bounds).
  [[nodiscard]] Index grid_size() const {
    if constexpr (Nx != Eigen::Dynamic) {
      return Nx;
    } else {
      return nx_;
    }
  }
  [[nodiscard]] Index steps() const { return steps_; }          ///< episode length m
  [[nodiscard]] Scalar horizon() const { return dt_ * static_cast<Scalar>(steps_); }  ///< T
  [[nodiscard]] Scalar length() const { return length_; }       ///< L
  [[nodiscard]] Scalar dx() const { return dx_; }
  /// x_j for the 0-based storage index j (the grid point j + 1 of the equations).
  [[nodiscard]] Scalar position(Index j) const { return static_cast<Scalar>(j + 1) * dx_; }
  /// All x_j (Nx).
  [[nodiscard]] Grid grid() const {
    Grid g;
    g.resize(grid_size());
    for (Index j = 0; j < grid_size(); ++j) g(j) = position(j);
    return g;
  }

  /// x (2Nx), u (1) → x_next (2Nx): one Crank–Nicolson step.
  void step(const State& x, const Control& u, State& x_next) const {
    check_sizes(x, u, "step");
    const Lu lu = factor(u(0));
    ComplexVector psi = apply(to_complex(x), u(0), Scalar(-1));  // U₂ψ
    lu.solve_in_place(psi);
    from_complex(psi, x_next);
  }

  /// A = ∂x_next/∂x (2Nx × 2Nx, independent of x) and B = ∂x_next/∂u (2Nx × 1) at (x, u).
  void jacobians(const State& x, const Control& u, StateJacobian& a, ControlJacobian& b) const {
    check_sizes(x, u, "jacobians");
    const Lu lu = factor(u(0));
    a.resize(state_dim(), state_dim());
    ComplexVector col;
    col.resize(grid_size());
    for (Index k = 0; k < grid_size(); ++k) {  // column k of M = U₁⁻¹ (U₂ e_k)
      col.setZero();
      col(k) = Complex(1);
      col = apply(col, u(0), Scalar(-1));
      lu.solve_in_place(col);
      for (Index j = 0; j < grid_size(); ++j) {  // ∂/∂Re ψ_k takes M e_k, ∂/∂Im ψ_k takes i·M e_k
        a(2 * j, 2 * k) = col(j).real();
        a(2 * j + 1, 2 * k) = col(j).imag();
        a(2 * j, 2 * k + 1) = -col(j).imag();
        a(2 * j + 1, 2 * k + 1) = col(j).real();
      }
    }
    ComplexVector rhs = sum_with_next(lu, x);  // ψ' + ψ
    const Complex ih(0, half_dt());
    for (Index j = 0; j < grid_size(); ++j) rhs(j) *= -ih * position(j);
    lu.solve_in_place(rhs);
    b.resize(state_dim());
    from_complex(rhs, b);
  }

  /// Aᵀλ and Bᵀλ in O(Nx) (derivation in the file comment). x, λ: 2Nx; u: 1.
  void vjp(const State& x, const Control& u, const State& lambda, State* lambda_x,
           Control* lambda_u) const {
    check_sizes(x, u, "vjp");
    detail::require(lambda.size() == state_dim(), "Schrodinger1D::vjp: lambda has size ",
                    lambda.size(), "; expected ", state_dim());
    if (!lambda_x && !lambda_u) return;
    const Lu lu = factor(u(0));
    ComplexVector mu = to_complex(lambda);
    lu.adjoint_solve_in_place(mu);  // μ = U₁⁻ᴴ λ
    if (lambda_x) from_complex(apply(mu, u(0), Scalar(1)), *lambda_x);  // U₁ μ
    if (lambda_u) {
      const ComplexVector s = sum_with_next(lu, x);
      Scalar acc = 0;
      for (Index j = 0; j < grid_size(); ++j) acc += position(j) * (std::conj(s(j)) * mu(j)).imag();
      (*lambda_u)(0) = -half_dt() * acc;
    }
  }

  /// `step` for every column of x (2Nx × B) and u (1 × B) into x_next (resized to 2Nx × B;
  /// it may be x itself). The samples run side by side in SIMD lanes (schrodinger_lanes.hpp):
  /// the same equations as `step`, in another order of operations, so the two agree to
  /// rounding, not bit for bit. A column's result does not depend on the other columns.
  void step_batch(const Matrix<Scalar>& x, const Matrix<Scalar>& u, Matrix<Scalar>& x_next) const
    requires(kLanesInStack)
  {
    check_batch(x, u, "step_batch");
    x_next.resize(state_dim(), x.cols());
    const Lanes lanes(half_dt(), dx_);
    typename Lanes::Field psi;
    for (Index first = 0; first < x.cols(); first += Lanes::kLanes) {
      const int count = detail::LaneRows<Scalar>::count(x.cols(), first);
      Lanes::load(x, first, count, psi);
      lanes.step(Lanes::load_controls(u, first, count), psi);
      Lanes::store(psi, first, count, x_next);
    }
  }

  /// `vjp` for every column of x (2Nx × B), u (1 × B) and lambda (2Nx × B): lambda_x (if not
  /// null) resized to 2Nx × B, lambda_u to 1 × B. As `step_batch`: equal to `vjp` to rounding.
  void vjp_batch(const Matrix<Scalar>& x, const Matrix<Scalar>& u, const Matrix<Scalar>& lambda,
                 Matrix<Scalar>* lambda_x, Matrix<Scalar>* lambda_u) const
    requires(kLanesInStack)
  {
    check_batch(x, u, "vjp_batch");
    detail::require(lambda.rows() == state_dim() && lambda.cols() == x.cols(),
                    "Schrodinger1D::vjp_batch: lambda is ", lambda.rows(), " x ", lambda.cols(),
                    "; expected ", state_dim(), " x ", x.cols());
    if (lambda_x) lambda_x->resize(state_dim(), x.cols());
    if (lambda_u) lambda_u->resize(1, x.cols());
    const Lanes lanes(half_dt(), dx_);
    typename Lanes::Field psi, cotangent, propagated;
    typename Lanes::LaneValues control_cotangent;
    for (Index first = 0; first < x.cols(); first += Lanes::kLanes) {
      const int count = detail::LaneRows<Scalar>::count(x.cols(), first);
      Lanes::load(x, first, count, psi);
      Lanes::load(lambda, first, count, cotangent);
      lanes.vjp(Lanes::load_controls(u, first, count), psi, cotangent,
                lambda_x ? &propagated : nullptr, control_cotangent);
      if (lambda_x) Lanes::store(propagated, first, count, *lambda_x);
      if (lambda_u)
        for (int l = 0; l < count; ++l)
          (*lambda_u)(0, first + l) = control_cotangent[static_cast<std::size_t>(l)];
    }
  }

  /// φ_n (2Nx), the n-th eigenstate of H(0) (n = 1 ground, 1 ≤ n ≤ Nx): sin(π n j/(Nx+1))
  /// normalised to Σ|φ|² = 1, real (imaginary parts 0). It does not depend on L or dt.
  [[nodiscard]] State eigenstate(Index n) const {
    check_level(n, "eigenstate");
    const Scalar scale = std::sqrt(Scalar(2) / static_cast<Scalar>(nx_ + 1));
    const Scalar angle = std::numbers::pi_v<Scalar> * static_cast<Scalar>(n) /
                         static_cast<Scalar>(nx_ + 1);
    State phi = State::Zero(state_dim());
    for (Index j = 0; j < grid_size(); ++j)
      phi(2 * j) = scale * std::sin(angle * static_cast<Scalar>(j + 1));
    return phi;
  }

  /// E_n = (4/dx²) sin²(πn / (2(Nx+1))), the eigenvalue of H(0) for φ_n (1 ≤ n ≤ Nx).
  [[nodiscard]] Scalar eigen_energy(Index n) const {
    check_level(n, "eigen_energy");
    const Scalar s = std::sin(std::numbers::pi_v<Scalar> * static_cast<Scalar>(n) /
                              (Scalar(2) * static_cast<Scalar>(nx_ + 1)));
    return Scalar(4) * inv_dx2_ * s * s;
  }

  /// |⟨φ, ψ⟩|² for φ, ψ (2Nx); `grad` (2Nx, optional) receives its gradient w.r.t. ψ.
  [[nodiscard]] Scalar fidelity(const State& phi, const State& psi, State* grad = nullptr) const {
    return detail::interleaved_fidelity(phi, psi, grad);
  }

  /// The paper's initial states ("1-1" weighting by default): 2Nx × count, one per column,
  ///     ψ₀ = (a₁φ₁ + a₂φ₂) / √(|a₁|² + |a₂|²),  a_k = c_k e^{i p_k},
  ///     c₁ = w·N(0,1), c₂ = N(0,1), p_k ~ U[0, 2π)   (w = `first_weight`; 3, 7, 15 for "w-1").
  /// Per sample the draws are c₁, c₂, p₁, p₂ in that order. Requires Nx ≥ 2.
  [[nodiscard]] Matrix<Scalar> initial_states(Rng& rng, Index count,
                                              Scalar first_weight = Scalar(1)) const {
    detail::require(count >= 0, "Schrodinger1D::initial_states: count = ", count,
                    "; expected >= 0");
    detail::require(std::isfinite(first_weight) && first_weight > 0,
                    "Schrodinger1D::initial_states: first_weight = ", first_weight,
                    "; expected a finite number > 0");
    const State phi1 = eigenstate(1), phi2 = eigenstate(2);
    Matrix<Scalar> out(state_dim(), count);
    for (Index b = 0; b < count; ++b) {
      const double c1 = static_cast<double>(first_weight) * rng.normal();
      const double c2 = rng.normal();
      const double p1 = rng.uniform(0.0, 2.0 * std::numbers::pi);
      const double p2 = rng.uniform(0.0, 2.0 * std::numbers::pi);
      const double norm = std::sqrt(c1 * c1 + c2 * c2);
      const auto a1 = static_cast<std::complex<Scalar>>(std::complex<double>(
          c1 * std::cos(p1) / norm, c1 * std::sin(p1) / norm));
      const auto a2 = static_cast<std::complex<Scalar>>(std::complex<double>(
          c2 * std::cos(p2) / norm, c2 * std::sin(p2) / norm));
      for (Index j = 0; j < grid_size(); ++j) {  // φ real: only its even entries are non-zero
        const Complex v = a1 * phi1(2 * j) + a2 * phi2(2 * j);
        out(2 * j, b) = v.real();
        out(2 * j + 1, b) = v.imag();
      }
    }
    return out;
  }

private:
  using Lu = ConstantTridiagonalLu<Complex, Nx>;
  using Lanes = detail::SchrodingerLanes<Scalar, Nx == Eigen::Dynamic ? 1 : Nx>;

  [[nodiscard]] Scalar half_dt() const { return dt_ / Scalar(2); }

  // i h H(u) on the diagonal at storage index j, and its constant off-diagonal.
  [[nodiscard]] Complex ih_diag(Index j, Scalar u) const {
    return Complex(0, half_dt() * (Scalar(2) * inv_dx2_ + u * position(j)));
  }
  [[nodiscard]] Complex ih_off() const { return Complex(0, -half_dt() * inv_dx2_); }

  [[nodiscard]] Lu factor(Scalar u) const {
    ComplexVector diag;
    diag.resize(grid_size());
    for (Index j = 0; j < grid_size(); ++j) diag(j) = Complex(1) + ih_diag(j, u);
    return Lu(diag, ih_off(), ih_off());
  }

  // (I + sign·i h H(u)) v: sign = +1 gives U₁, −1 gives U₂.
  [[nodiscard]] ComplexVector apply(const ComplexVector& v, Scalar u, Scalar sign) const {
    ComplexVector out;
    out.resize(grid_size());
    const Complex off = sign * ih_off();
    for (Index j = 0; j < grid_size(); ++j) {
      Complex acc = v(j) + sign * ih_diag(j, u) * v(j);
      if (j > 0) acc += off * v(j - 1);
      if (j + 1 < grid_size()) acc += off * v(j + 1);
      out(j) = acc;
    }
    return out;
  }

  // ψ' + ψ = 2 U₁⁻¹ ψ: one solve instead of a step plus an addition.
  [[nodiscard]] ComplexVector sum_with_next(const Lu& lu, const State& x) const {
    ComplexVector s = to_complex(x);
    lu.solve_in_place(s);
    s *= Complex(2);
    return s;
  }

  [[nodiscard]] ComplexVector to_complex(const State& x) const {
    ComplexVector psi;
    psi.resize(grid_size());
    for (Index j = 0; j < grid_size(); ++j) psi(j) = Complex(x(2 * j), x(2 * j + 1));
    return psi;
  }

  template <class Out>
  void from_complex(const ComplexVector& psi, Out& x) const {
    x.resize(state_dim());
    for (Index j = 0; j < grid_size(); ++j) {
      x(2 * j) = psi(j).real();
      x(2 * j + 1) = psi(j).imag();
    }
  }

  void check_sizes(const State& x, const Control& u, const char* where) const {
    detail::require(x.size() == state_dim(), "Schrodinger1D::", where, ": state has size ",
                    x.size(), "; expected ", state_dim());
    detail::require(u.size() == 1, "Schrodinger1D::", where, ": control has size ", u.size(),
                    "; expected 1");
  }

  void check_batch(const Matrix<Scalar>& x, const Matrix<Scalar>& u, const char* where) const {
    detail::require(x.rows() == state_dim(), "Schrodinger1D::", where, ": states have ",
                    x.rows(), " rows; expected ", state_dim());
    detail::require(u.rows() == 1 && u.cols() == x.cols(), "Schrodinger1D::", where,
                    ": controls are ", u.rows(), " x ", u.cols(), "; expected 1 x ", x.cols());
  }

  void check_level(Index n, const char* where) const {
    detail::require(n >= 1 && n <= nx_, "Schrodinger1D::", where, ": n = ", n,
                    "; expected 1 <= n <= Nx = ", nx_, " (n = 1 is the ground state)");
  }

  Index nx_;
  Scalar dt_;
  Index steps_;
  Scalar length_;
  Scalar dx_ = 0;
  Scalar inv_dx2_ = 0;
};

/// The paper's per-step loss ℓ(ψ) = 1 − |⟨φ_target, ψ⟩|² (state 2Nx), with its gradient.
///
/// `target` is the 1-based eigenstate index n (1 = ground), as the paper's code counts (TS).
/// The paper's plots count from 0: "target state 2" there is n = 3 here (TS ∈ {3, 4, 5} ↔
/// plot targets 2, 3, 4).
template <class Scalar = double, int Nx = 32>
class QuantumInfidelityLoss {
public:
  using Sim = Schrodinger1D<Scalar, Nx>;
  using State = typename Sim::State;

  QuantumInfidelityLoss(const Sim& sim, Index target)
      : target_index_(target), target_(sim.eigenstate(target)) {}

  /// Throws `InvalidArgument` unless φ_n has `state_dim` entries; the engine calls it when it
  /// is built (with `Nx = Eigen::Dynamic` the loss may come from a grid of another size).
  void check_state_dim(Index state_dim) const {
    detail::require(target_.size() == state_dim, "QuantumInfidelityLoss: the target state has ",
                    target_.size(), " entries; expected the simulator's state_dim = ", state_dim);
  }

  /// ℓ(x) for x (2Nx); `grad` (2Nx, optional) receives ∂ℓ/∂x.
  Scalar operator()(const State& x, State* grad) const {
    const Scalar f = detail::interleaved_fidelity(target_, x, grad);
    if (grad) *grad = -*grad;
    return Scalar(1) - f;
  }

  [[nodiscard]] Index target_index() const { return target_index_; }  ///< n, 1 = ground
  [[nodiscard]] const State& target() const { return target_; }       ///< φ_n (2Nx)

private:
  Index target_index_;
  State target_;
};

static_assert(Simulator<Schrodinger1D<double>>);
static_assert(Simulator<Schrodinger1D<float, 8>>);
static_assert(Simulator<Schrodinger1D<double, Eigen::Dynamic>>);
static_assert(StateLoss<QuantumInfidelityLoss<double>, Schrodinger1D<double>::State>);

}  // namespace sbptt
