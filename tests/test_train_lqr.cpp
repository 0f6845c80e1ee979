// Convergence where the answer is known (the LQR question of the ICLR review): the Riccati
// reference of examples/common/lqr.hpp against closed forms, then R training the linear
// feedback u = −K x to the optimum on a small stable system.
#include <catch2/catch.hpp>

#include <cmath>

#include "sbptt/bptt/losses.hpp"
#include "sbptt/core/controller_check.hpp"
#include "sbptt/core/rng.hpp"
#include "sbptt/optim/adam.hpp"
#include "sbptt/sim/linear.hpp"
#include "sbptt/train/trainer.hpp"
#include "linear_feedback.hpp"
#include "lqr.hpp"

using namespace sbptt;
using lqr::Mat;
using lqr::Vec;

namespace {

using Sim = LinearSystem<double>;
using Loss = SquaredDistanceLoss<Sim::State>;
using Feedback = testing::LinearFeedback<double>;

/// x' = 0.9 · rotation(0.3) x + (0, 1)ᵀ u: stable, controllable (the study's s = 0.9 scene).
lqr::Problem stable_problem(int steps, double control_cost) {
  Mat a(2, 2), b(2, 1);
  a << std::cos(0.3), -std::sin(0.3), std::sin(0.3), std::cos(0.3);
  a *= 0.9;
  b << 0, 1;
  return lqr::Problem::from_objective(a, b, 1.0, control_cost * steps / 2.0, steps);
}

Mat normal_states(Index rows, Index cols, std::uint64_t seed) {
  Rng rng(seed);
  Mat x(rows, cols);
  for (Index i = 0; i < x.size(); ++i) x(i) = rng.normal();
  return x;
}

/// The engine objective whose loss `lqr::constant_gain_loss` claims to be (Q = I, R = r I).
Objective<Loss> engine_objective(const lqr::Problem& p) {
  const double rho = p.r(0, 0) * p.steps * static_cast<double>(p.b.cols()) / 2.0;
  return {Loss{Sim::State::Zero(p.a.rows())}, LossTiming::Continuous, 1.0, rho};
}

}  // namespace

TEST_CASE("lqr: the scalar recursion converges to the closed-form root of the scalar DARE",
          "[lqr]") {
  // p = q + a²p − a²b²p²/(r + b²p)  ⇔  b²p² + (r(1 − a²) − q b²) p − q r = 0, positive root.
  for (double a : {0.5, 1.0, 1.3}) {
    const double b = 0.7, q = 1.0, r = 0.2;
    const double lin = r * (1 - a * a) - q * b * b;
    const double p_inf = (-lin + std::sqrt(lin * lin + 4 * b * b * q * r)) / (2 * b * b);
    const double k_inf = b * p_inf * a / (r + b * b * p_inf);
    lqr::Problem problem{Mat::Constant(1, 1, a), Mat::Constant(1, 1, b), Mat::Constant(1, 1, q),
                         Mat::Constant(1, 1, r), 200};
    const auto solution = lqr::riccati(problem);
    INFO("a = " << a);
    CHECK(solution.cost_to_go[0](0, 0) == Approx(p_inf).epsilon(1e-12));
    CHECK(solution.gains[0](0, 0) == Approx(k_inf).epsilon(1e-12));
    CHECK(lqr::dare(problem)(0, 0) == Approx(p_inf).epsilon(1e-12));
    // The last gain sees only the terminal weight: k_{m-1} = b q a / (r + b² q).
    CHECK(solution.gains.back()(0, 0) == Approx(b * q * a / (r + b * b * q)).epsilon(1e-14));
  }
}

TEST_CASE("lqr: the Riccati controls and cost equal the least-squares open-loop optimum",
          "[lqr]") {
  // Stacked: x_n = Aⁿ x_0 + Σ_{j<n} A^{n-1-j} B u_j, so J(u) = ½ uᵀ H u + fᵀ u + c with
  // H = R̄ + Γᵀ Q̄ Γ and f = Γᵀ Q̄ Φ x_0; the minimiser u* = −H⁻¹ f, found without Riccati.
  Mat a(2, 2), b(2, 1);
  a << 1.2, 0.4, -0.3, 0.9;  // unstable (eigenvalues 1.05 ± 0.31i)
  b << 0.2, 1.0;
  const int m = 6;
  lqr::Problem problem{a, b, Mat::Identity(2, 2), Mat::Constant(1, 1, 0.3), m};
  Vec x0(2);
  x0 << 0.7, -1.1;

  Mat phi((m + 1) * 2, 2), gamma = Mat::Zero((m + 1) * 2, m);
  Mat power = Mat::Identity(2, 2);
  for (int n = 0; n <= m; ++n) {
    phi.middleRows(2 * n, 2) = power;
    power = a * power;
  }
  for (int n = 1; n <= m; ++n)
    for (int j = 0; j < n; ++j) gamma.block(2 * n, j, 2, 1) = phi.middleRows(2 * (n - 1 - j), 2) * b;
  const Mat q_bar = Mat::Identity((m + 1) * 2, (m + 1) * 2);
  const Mat h = problem.r(0, 0) * Mat::Identity(m, m) + gamma.transpose() * q_bar * gamma;
  const Vec f = gamma.transpose() * q_bar * phi * x0;
  const Vec u_star = -h.ldlt().solve(f);
  const double j_star = 0.5 * x0.dot(phi.transpose() * q_bar * phi * x0) + 0.5 * f.dot(u_star);

  const auto solution = lqr::riccati(problem);
  CHECK(0.5 * x0.dot(solution.cost_to_go[0] * x0) == Approx(j_star).epsilon(1e-12));
  Vec x = x0;
  for (int n = 0; n < m; ++n) {
    const double u = -(solution.gains[static_cast<std::size_t>(n)] * x)(0);
    INFO("step " << n);
    CHECK(u == Approx(u_star(n)).epsilon(1e-11));
    x = a * x + b * u;
  }
}

TEST_CASE("lqr: the closed-form constant-gain loss equals the engine's loss", "[lqr]") {
  const auto problem = stable_problem(7, 0.1);
  const Mat x0 = normal_states(2, 5, 3);
  const Sim sim(problem.a, problem.b);
  Feedback feedback(2, 1);
  feedback.params() << 0.4, -0.8;
  Engine engine(sim, feedback, engine_objective(problem), problem.steps);
  const double loss = engine.forward(x0);
  const Mat second_moment = x0 * x0.transpose() / 5.0;
  CHECK(lqr::constant_gain_loss(problem, feedback.gain(), second_moment) ==
        Approx(loss).epsilon(1e-13));
}

TEST_CASE("lqr: the linear feedback's products equal finite differences", "[lqr]") {
  Feedback feedback(3, 2);
  feedback.params() << 0.3, -1.2, 0.5, 0.8, 0.1, -0.4;
  CHECK(check_controller(feedback, normal_states(3, 4, 5)).worst() < 1e-8);
}

TEST_CASE("lqr: R trains the constant gain to the optimum on a small stable system", "[lqr]") {
  // With m = 1 a constant gain can be the Riccati gain itself; with m = 5 it cannot, and the
  // target is the best constant gain K̄*, found by Newton on finite differences of the closed
  // form (stationary: its finite-difference gradient vanishes, its Hessian is positive).
  for (int steps : {1, 5}) {
    const auto problem = stable_problem(steps, 0.1);
    const Mat x0 = normal_states(2, 64, 1);
    const Mat second_moment = x0 * x0.transpose() / 64.0;
    const auto riccati = lqr::riccati(problem);
    const double riccati_loss = lqr::optimal_loss(problem, second_moment);
    const auto best = lqr::optimal_constant_gain(problem, second_moment, riccati.gains[0]);
    INFO("steps " << steps);
    REQUIRE(best.gradient_norm < 1e-9);
    REQUIRE(best.min_hessian_eigenvalue > 0.1);
    // Riccati is a lower bound that any constant gain (K_0 among them) pays at least.
    CHECK(riccati_loss <= best.loss * (1 + 1e-14));
    CHECK(best.loss <= lqr::constant_gain_loss(problem, riccati.gains[0], second_moment));

    const Sim sim(problem.a, problem.b);
    Feedback feedback(2, 1);
    TrainerOptions options;
    options.method = Method::Regular;
    options.batch = x0.cols();
    Trainer trainer(sim, feedback, engine_objective(problem), problem.steps,
                    Adam<double>(AdamOptions<double>{0.01}), options);
    for (int epoch = 0; epoch < 1500; ++epoch) trainer.train_epoch(x0, x0);
    REQUIRE_FALSE(trainer.stopped());
    const Mat gain = feedback.gain();
    const double loss = lqr::constant_gain_loss(problem, gain, second_moment);
    CHECK((gain - best.gain).norm() < 1e-6);
    CHECK(loss - best.loss < 1e-10 * best.loss);
    if (steps == 1) {
      CHECK((gain - riccati.gains[0]).norm() < 1e-6);
      CHECK(loss == Approx(riccati_loss).epsilon(1e-10));
    } else {
      // The constant gain pays for not being time-varying: 0.9 % above Riccati (the study).
      CHECK(loss / riccati_loss - 1 == Approx(0.009).margin(0.001));
    }
  }
}
