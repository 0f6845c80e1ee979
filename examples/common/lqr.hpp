#pragma once
// Linear-quadratic regulation: the known answer of the LQR convergence study and its test.
//
//     x_{n+1} = A x_n + B u_n,    J = Σ_{n=0}^{m-1} ½ (x_nᵀ Q x_n + u_nᵀ R u_n) + ½ x_mᵀ Q x_m
//
// A: d × d, B: d × k, Q: d × d (symmetric ≥ 0), R: k × k (symmetric > 0), m steps.
// The backward Riccati recursion, from P_m = Q,
//
//     K_n = (R + Bᵀ P_{n+1} B)⁻¹ Bᵀ P_{n+1} A,     P_n = Q + Aᵀ P_{n+1} (A − B K_n),
//
// gives the optimal time-varying feedback u_n = −K_n x_n and the optimal cost ½ x_0ᵀ P_0 x_0,
// for every x_0. The engine's objective (a continuous loss ½‖x_n‖² with step weight w and
// control weight ρ, see sbptt/bptt/objective.hpp) is this J with Q = w I and R = 2ρ/(m k) I,
// less ½ x_0ᵀ Q x_0, which it does not score: x_0 is data.
//
// A controller u = −K x with one constant gain cannot follow the time-varying K_n, so its best
// loss J(K̄*) lies above the Riccati optimum; `optimal_constant_gain` finds K̄* by Newton's
// method on central finite differences of `constant_gain_loss`, with nothing from the engine.
#include <cmath>
#include <functional>
#include <tuple>
#include <utility>
#include <vector>

#include <Eigen/Eigenvalues>

#include "sbptt/core/error.hpp"
#include "sbptt/core/finite_difference.hpp"

namespace sbptt::lqr {

using Mat = Eigen::MatrixXd;
using Vec = Eigen::VectorXd;

struct Problem {
  Mat a, b, q, r;  ///< A (d × d), B (d × k), Q (d × d), R (k × k)
  int steps = 1;   ///< m

  /// The problem the engine solves with a continuous ½‖x‖² loss of step weight w and control
  /// weight ρ over m steps (see the file comment).
  static Problem from_objective(Mat a, Mat b, double step_weight, double control_weight,
                                int steps) {
    const auto d = a.rows(), k = b.cols();
    Problem p{std::move(a), std::move(b), step_weight * Mat::Identity(d, d),
              2 * control_weight / (steps * static_cast<double>(k)) * Mat::Identity(k, k), steps};
    detail::require(steps >= 1, "lqr::Problem: steps = ", steps, "; expected at least 1");
    return p;
  }
};

struct RiccatiSolution {
  std::vector<Mat> gains;       ///< K_0 … K_{m-1} (k × d each)
  std::vector<Mat> cost_to_go;  ///< P_0 … P_m (d × d each)
};

/// One step of the recursion: K_n (k × d) and P_n (d × d) from P_{n+1} (d × d).
inline std::pair<Mat, Mat> riccati_step(const Problem& p, const Mat& next) {
  const Mat bp = p.b.transpose() * next;
  Mat gain = (p.r + bp * p.b).ldlt().solve(bp * p.a);
  const Mat cost = p.q + p.a.transpose() * next * (p.a - p.b * gain);
  return {std::move(gain), 0.5 * (cost + cost.transpose())};  // symmetric up to round-off
}

/// The backward Riccati recursion of the file comment.
inline RiccatiSolution riccati(const Problem& p) {
  RiccatiSolution s;
  const auto m = static_cast<std::size_t>(p.steps);
  s.gains.resize(m);
  s.cost_to_go.resize(m + 1);
  s.cost_to_go[m] = p.q;
  for (std::size_t n = m; n-- > 0;)
    std::tie(s.gains[n], s.cost_to_go[n]) = riccati_step(p, s.cost_to_go[n + 1]);
  return s;
}

/// The engine's loss at the Riccati optimum, averaged over initial states whose second moment
/// is S = X Xᵀ / N (d × d): ½ tr((P_0 − Q) S).
inline double optimal_loss(const Problem& p, const Mat& second_moment) {
  return 0.5 * ((riccati(p).cost_to_go[0] - p.q) * second_moment).trace();
}

/// The engine's loss of the constant feedback u = −K x (K: k × d) over the same states:
/// Σ_{n<m} ½ tr(Kᵀ R K S_n) + Σ_{n=1}^{m} ½ tr(Q S_n), with S_{n+1} = (A − BK) S_n (A − BK)ᵀ.
inline double constant_gain_loss(const Problem& p, const Mat& gain, const Mat& second_moment) {
  const Mat closed = p.a - p.b * gain;
  const Mat control_cost = gain.transpose() * p.r * gain;
  Mat s = second_moment;
  double loss = 0;
  for (int n = 0; n < p.steps; ++n) {
    loss += 0.5 * (control_cost * s).trace();
    s = closed * s * closed.transpose();
    loss += 0.5 * (p.q * s).trace();
  }
  return loss;
}

/// The stabilising solution of the discrete algebraic Riccati equation
/// P = Q + Aᵀ P A − Aᵀ P B (R + Bᵀ P B)⁻¹ Bᵀ P A, as the limit of the recursion from P = Q.
inline Mat dare(const Problem& p, double tolerance = 1e-14, int max_iterations = 1000000) {
  Mat cost = p.q;
  for (int i = 0; i < max_iterations; ++i) {
    Mat next = riccati_step(p, cost).second;
    const double change = (next - cost).norm();
    cost = std::move(next);
    if (change <= tolerance * cost.norm()) return cost;
  }
  throw Error(detail::concat("lqr::dare: no convergence in ", max_iterations,
                             " iterations; is (A, B) stabilisable?"));
}

/// The row-major flat vector of a gain (as `LinearFeedback` stores it) and back.
inline Vec flatten(const Mat& gain) {
  Vec v(gain.size());
  for (Index i = 0; i < gain.rows(); ++i)
    for (Index j = 0; j < gain.cols(); ++j) v(i * gain.cols() + j) = gain(i, j);
  return v;
}
inline Mat unflatten(const Vec& v, Index rows, Index cols) {
  Mat gain(rows, cols);
  for (Index i = 0; i < rows; ++i)
    for (Index j = 0; j < cols; ++j) gain(i, j) = v(i * cols + j);
  return gain;
}

/// A zero of a vector field f: Rⁿ → Rⁿ by Newton's method with a central-difference Jacobian,
/// the step halved until ‖f‖ decreases. Returns the point; `residual` gets ‖f‖ there.
inline Vec newton_root(const std::function<void(const Vec&, Vec&)>& field, Vec x,
                       double* residual = nullptr, int max_iterations = 100) {
  const Index n = x.size();
  Vec f(n), trial(n), f_trial(n);
  field(x, f);
  for (int it = 0; it < max_iterations && f.norm() > 0; ++it) {
    const Mat jac = finite_difference_jacobian<double>(field, x, n, 1e-4);
    const Vec step = jac.fullPivLu().solve(-f);
    double scale = 1;
    bool improved = false;
    for (int halving = 0; halving < 40 && !improved; ++halving, scale *= 0.5) {
      trial = x + scale * step;
      field(trial, f_trial);
      improved = f_trial.allFinite() && f_trial.norm() < f.norm();
    }
    if (!improved) break;  // at the resolution of the finite differences
    x = trial;
    f = f_trial;
  }
  if (residual) *residual = f.norm();
  return x;
}

struct ConstantGainOptimum {
  Mat gain;                          ///< K̄* (k × d)
  double loss = 0;                   ///< J(K̄*)
  double gradient_norm = 0;          ///< ‖∇J(K̄*)‖ by central differences
  double min_hessian_eigenvalue = 0; ///< > 0: a strict local minimum
};

/// Central-difference gradient of `constant_gain_loss` in the flat gain (k·d).
inline Vec constant_gain_gradient(const Problem& p, const Vec& flat, const Mat& second_moment) {
  const auto k = p.b.cols(), d = p.a.rows();
  auto loss = [&](const Vec& v, Vec& out) {
    out.resize(1);
    out(0) = constant_gain_loss(p, unflatten(v, k, d), second_moment);
  };
  return finite_difference_jacobian<double>(loss, flat, 1).row(0).transpose();
}

/// The best constant gain K̄* for the finite-horizon loss, by Newton from `start` (k × d).
inline ConstantGainOptimum optimal_constant_gain(const Problem& p, const Mat& second_moment,
                                                 const Mat& start) {
  const auto k = p.b.cols(), d = p.a.rows();
  auto gradient = [&](const Vec& v, Vec& out) {
    out = constant_gain_gradient(p, v, second_moment);
  };
  ConstantGainOptimum o;
  const Vec best = newton_root(gradient, flatten(start), &o.gradient_norm);
  o.gain = unflatten(best, k, d);
  o.loss = constant_gain_loss(p, o.gain, second_moment);
  const Mat hessian = finite_difference_jacobian<double>(gradient, best, best.size(), 1e-4);
  o.min_hessian_eigenvalue =
      Eigen::SelfAdjointEigenSolver<Mat>(0.5 * (hessian + hessian.transpose()))
          .eigenvalues()
          .minCoeff();
  return o;
}

}  // namespace sbptt::lqr
