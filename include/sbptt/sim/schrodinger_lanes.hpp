#pragma once
/// \file The Crank–Nicolson step of `Schrodinger1D` and its vjp for a block of samples side by
/// side: sample l of the block is lane l of every array, so each arithmetic line below is one
/// SIMD instruction over the block instead of one scalar operation per sample.
///
/// Why: per sample the step is three recurrences along the grid (pivots, forward and back
/// substitution), each link waiting for the one before; one sample keeps one lane of the core
/// busy and the rest wait. Across samples the recurrences are independent.
///
/// Equations (schrodinger.hpp), per lane, for the grid points j = 0 … Nx − 1 at x_j = (j + 1)·dx,
/// with h = dt/2, k = h/dx², δ_j = 2k + h·u·x_j, and walls ψ_{−1} = ψ_{Nx} = 0:
///
///     U₁ = I + i h H(u): diagonal 1 + iδ_j, off-diagonals −ik;  U₂ = U₁ᴴ
///     pivots p_0 = 1 + iδ_0,  p_j = 1 + iδ_j + k² r_{j−1},  r_j = 1/p_j   (Re p_j ≥ 1)
///     solve U₁y = b:   y_j = b_j + ik·r_{j−1}y_{j−1} (j ↑),  y_j = (y_j + ik·y_{j+1})·r_j (j ↓)
///     solve U₁ᴴμ = λ:  z_j = (λ_j − ik·z_{j−1})·conj(r_j) (j ↑),  μ_j = z_j − ik·conj(r_j)μ_{j+1} (j ↓)
///     step:  ψ' = U₁⁻¹U₂ψ
///     vjp:   Aᵀλ = U₁μ,  Bᵀλ = −h Σ_j x_j Im(conj(s_j) μ_j),  s = ψ + ψ' = 2U₁⁻¹ψ
///
/// Re p_j ≥ 1 by induction (Re r_{j−1} = Re p_{j−1}/|p_{j−1}|² > 0), so |p_j|² ≥ 1: the
/// reciprocal conj(p)/|p|² needs no zero check and cannot underflow. It is not rescaled
/// against overflow, which the per-sample step does: |p|² overflows once |δ| passes about
/// 1.8e19 in float (|u| ≈ 3e20 at the paper's settings; 1e154 in double), and then r = 0 and
/// the step is no longer unitary. Controls that large only come from a diverged run.
///
/// Layout: a block is kLanes samples (64 bytes of each grid value: 16 floats or 8 doubles);
/// `re[i][l]`, `im[i][l]` hold ψ_j of lane l at row i = j + 1. Rows 0 and Nx + 1 are the
/// walls, always 0, so that ψ_{−1} = ψ_{Nx} = 0 and r_{−1} = y_{−1} = 0 need no branch. A
/// batch's last, partial block is padded with ψ = 0, u = 0, λ = 0, so that every block runs
/// the same instructions: a sample's result does not depend on its place in the batch or on
/// the batch's size.
#include <algorithm>
#include <array>
#include <cstddef>

#include "sbptt/core/types.hpp"
#include "sbptt/sim/lane_rows.hpp"

namespace sbptt::detail {

template <class Scalar, int Nx>
class SchrodingerLanes {
public:
  static constexpr int kLanes = LaneRows<Scalar>::kLanes;
  static constexpr int kRows = Nx + 2;  // the grid and a wall on either side
  using LaneValues = std::array<Scalar, kLanes>;  // one number per sample of the block
  /// The 2Nx rows of a block of a batch as lane arrays, in the batch's order (Re ψ_0, Im ψ_0,
  /// …): the tiles of lane_rows.hpp transpose a block whole, and `Field` keeps Re and Im
  /// apart, so `load` and `store` pass through these.
  using Rows = std::array<typename LaneRows<Scalar>::Values, static_cast<std::size_t>(2 * Nx)>;
  struct alignas(64) Field {  // one complex value per row and lane; the walls are 0
    Scalar re[kRows][kLanes];
    Scalar im[kRows][kLanes];
    void clear_walls() {
      for (int i : {0, kRows - 1}) {
        std::fill_n(re[i], kLanes, Scalar(0));
        std::fill_n(im[i], kLanes, Scalar(0));
      }
    }
  };

  /// h = dt/2, dx: the grid spacing.
  SchrodingerLanes(Scalar half_dt, Scalar dx)
      : h_(half_dt), k_(half_dt / (dx * dx)), k2_(k_ * k_), dx_(dx) {}

  /// Columns first … first + count − 1 of `x` (2Nx × B, interleaved Re/Im) into `f`, the
  /// lanes past `count` set to 0.
  static void load(const Matrix<Scalar>& x, Index first, int count, Field& f) {
    f.clear_walls();
    Rows rows;
    LaneRows<Scalar>::load_rows(x, first, count, rows);
    for (std::size_t j = 0; 2 * j < rows.size(); ++j) {
      std::copy_n(rows[2 * j].data(), kLanes, f.re[j + 1]);
      std::copy_n(rows[2 * j + 1].data(), kLanes, f.im[j + 1]);
    }
  }
  static void store(const Field& f, Index first, int count, Matrix<Scalar>& x) {
    Rows rows;
    for (std::size_t j = 0; 2 * j < rows.size(); ++j) {
      std::copy_n(f.re[j + 1], kLanes, rows[2 * j].data());
      std::copy_n(f.im[j + 1], kLanes, rows[2 * j + 1].data());
    }
    LaneRows<Scalar>::store_rows(rows, first, count, x);
  }
  static LaneValues load_controls(const Matrix<Scalar>& u, Index first, int count) {
    LaneValues out{};
    for (int l = 0; l < count; ++l) out[static_cast<std::size_t>(l)] = u(0, first + l);
    return out;
  }

  /// psi ← U₁⁻¹U₂ psi for every lane.
  void step(const LaneValues& u, Field& psi) const {
    Field r, y;  // r: 1/p_j; y: U₂ψ, then forward- and back-substituted
    r.clear_walls();
    y.clear_walls();
    for (int i = 1; i <= Nx; ++i) {
      const Scalar hx = h_ * position(i);
      for (int l = 0; l < kLanes; ++l) {
        const Scalar delta = Scalar(2) * k_ + hx * u[static_cast<std::size_t>(l)];
        pivot(i, l, delta, r);
        const Scalar br = psi.re[i][l] + delta * psi.im[i][l] -  // b = U₂ψ
                          k_ * (psi.im[i - 1][l] + psi.im[i + 1][l]);
        const Scalar bi = psi.im[i][l] - delta * psi.re[i][l] +
                          k_ * (psi.re[i - 1][l] + psi.re[i + 1][l]);
        forward_link(r, i, l, br, bi, y);
      }
    }
    for (int i = Nx; i >= 1; --i) {
      for (int l = 0; l < kLanes; ++l) {
        back_link(r, i, l, y);
        psi.re[i][l] = y.re[i][l];
        psi.im[i][l] = y.im[i][l];
      }
    }
  }

  /// For every lane, with psi the state before the step and lambda the cotangent of the
  /// state after it: lambda_x ← Aᵀλ (if not null), lambda_u ← Bᵀλ.
  void vjp(const LaneValues& u, const Field& psi, const Field& lambda, Field* lambda_x,
           LaneValues& lambda_u) const {
    Field r, y, mu;  // y: U₁⁻¹ψ = s/2; mu: Uᴴ⁻¹λ, then U₁⁻ᴴλ
    r.clear_walls();
    y.clear_walls();
    mu.clear_walls();
    for (int i = 1; i <= Nx; ++i) {
      const Scalar hx = h_ * position(i);
      for (int l = 0; l < kLanes; ++l) {
        pivot(i, l, Scalar(2) * k_ + hx * u[static_cast<std::size_t>(l)], r);
        forward_link(r, i, l, psi.re[i][l], psi.im[i][l], y);
        const Scalar zr = lambda.re[i][l] + k_ * mu.im[i - 1][l];  // (λ_j − ik z_{j−1})
        const Scalar zi = lambda.im[i][l] - k_ * mu.re[i - 1][l];
        const Scalar rr = r.re[i][l], ri = r.im[i][l];  // × conj(r_j)
        mu.re[i][l] = zr * rr + zi * ri;
        mu.im[i][l] = zi * rr - zr * ri;
      }
    }
    LaneValues acc{};
    for (int i = Nx; i >= 1; --i) {
      const Scalar x = position(i);
      for (int l = 0; l < kLanes; ++l) {
        back_link(r, i, l, y);
        const Scalar rr = r.re[i][l], ri = r.im[i][l];  // μ_j = z_j − ik conj(r_j) μ_{j+1}
        const Scalar wr = k_ * mu.re[i + 1][l], wi = k_ * mu.im[i + 1][l];
        mu.re[i][l] += rr * wi - ri * wr;
        mu.im[i][l] -= rr * wr + ri * wi;
        acc[static_cast<std::size_t>(l)] +=
            x * (y.re[i][l] * mu.im[i][l] - y.im[i][l] * mu.re[i][l]);
      }
    }
    for (int l = 0; l < kLanes; ++l)
      lambda_u[static_cast<std::size_t>(l)] = Scalar(-2) * h_ * acc[static_cast<std::size_t>(l)];
    if (!lambda_x) return;
    lambda_x->clear_walls();
    for (int i = 1; i <= Nx; ++i) {  // U₁μ
      const Scalar hx = h_ * position(i);
      for (int l = 0; l < kLanes; ++l) {
        const Scalar delta = Scalar(2) * k_ + hx * u[static_cast<std::size_t>(l)];
        lambda_x->re[i][l] = mu.re[i][l] - delta * mu.im[i][l] +
                             k_ * (mu.im[i - 1][l] + mu.im[i + 1][l]);
        lambda_x->im[i][l] = mu.im[i][l] + delta * mu.re[i][l] -
                             k_ * (mu.re[i - 1][l] + mu.re[i + 1][l]);
      }
    }
  }

private:
  [[nodiscard]] Scalar position(int i) const { return static_cast<Scalar>(i) * dx_; }  // x_j

  // r_j = 1/p_j, p_j = 1 + iδ_j + k² r_{j−1} (r_{−1} = 0 in the wall row).
  void pivot(int i, int l, Scalar delta, Field& r) const {
    const Scalar pr = Scalar(1) + k2_ * r.re[i - 1][l];
    const Scalar pi = delta + k2_ * r.im[i - 1][l];
    const Scalar inv_norm = Scalar(1) / (pr * pr + pi * pi);
    r.re[i][l] = pr * inv_norm;
    r.im[i][l] = -pi * inv_norm;
  }

  // y_j = b_j + ik·r_{j−1}·y_{j−1}: one link of the forward substitution with L.
  void forward_link(const Field& r, int i, int l, Scalar br, Scalar bi, Field& y) const {
    const Scalar rr = r.re[i - 1][l], ri = r.im[i - 1][l];
    const Scalar tr = rr * y.re[i - 1][l] - ri * y.im[i - 1][l];
    const Scalar ti = rr * y.im[i - 1][l] + ri * y.re[i - 1][l];
    y.re[i][l] = br - k_ * ti;
    y.im[i][l] = bi + k_ * tr;
  }

  // y_j ← (y_j + ik·y_{j+1})·r_j: one link of the back substitution with U.
  void back_link(const Field& r, int i, int l, Field& y) const {
    const Scalar yr = y.re[i][l] - k_ * y.im[i + 1][l];
    const Scalar yi = y.im[i][l] + k_ * y.re[i + 1][l];
    const Scalar rr = r.re[i][l], ri = r.im[i][l];
    y.re[i][l] = yr * rr - yi * ri;
    y.im[i][l] = yr * ri + yi * rr;
  }

  Scalar h_;
  Scalar k_;
  Scalar k2_;
  Scalar dx_;
};

}  // namespace sbptt::detail
