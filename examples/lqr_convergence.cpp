// Convergence where the answer is known: R, M and C train the linear feedback u = −K x on
// x' = A x + B u with the quadratic loss Σ_{n=1}^{m} ½‖x_n‖² + r/2 Σ_{n<m} ‖u_n‖², and are
// compared with the Riccati optimum (examples/common/lqr.hpp). docs/results.md reads the table.
//
// Scene: d = 2, k = 1, A = s · rotation(0.3 rad) (spectral radius s), B = (0, 1)ᵀ, r = 0.1,
// 64 initial states drawn from N(0, I) (seed 1), the whole set as one batch (so the trained
// loss is a deterministic function of K), Adam at lr 0.01, K = 0 at the start.
//
// For each spectral radius s and horizon m, the program prints the references
//   K_0      the first gain of the Riccati (time-varying) optimum, J_ric its loss;
//   K̄*      the best constant gain (Newton on finite differences of the closed-form loss,
//            nothing from the engine), J̄* its loss, and ‖∇J‖ there;
//   K_M      the fixed point of M (Newton on the engine's PhysicsOnly sweep), J(K_M);
// then, for R, M and C at a few epochs, ‖K − K̄*‖ and the relative loss gap (J(K) − J̄*)/J̄*.
//
// Usage: lqr_convergence        (no options but --help; about a minute)
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <exception>
#include <string>
#include <string_view>
#include <vector>

#include "sbptt/bptt/losses.hpp"
#include "sbptt/core/rng.hpp"
#include "sbptt/optim/adam.hpp"
#include "sbptt/sim/linear.hpp"
#include "sbptt/train/trainer.hpp"
#include "write_signals.hpp"
#include "linear_feedback.hpp"
#include "lqr.hpp"
#include "standard_streams.hpp"

using namespace sbptt;
using lqr::Mat;
using lqr::Vec;

namespace {

using Sim = LinearSystem<double>;
using Loss = SquaredDistanceLoss<Sim::State>;
using Feedback = testing::LinearFeedback<double>;

constexpr double control_cost = 0.1;  // r: R = r I
constexpr long epochs = 10000;
const std::vector<long> report_epochs{10, 100, 1000, 3000, 10000};

struct Scene {
  lqr::Problem problem;
  Mat starts;         ///< d × N initial states
  Mat second_moment;  ///< X Xᵀ / N
};

Scene make_scene(double radius, int steps) {
  const double angle = 0.3;
  Mat a(2, 2), b(2, 1);
  a << std::cos(angle), -std::sin(angle), std::sin(angle), std::cos(angle);
  a *= radius;
  b << 0, 1;
  Scene s{lqr::Problem::from_objective(a, b, 1.0, control_cost * steps / 2.0, steps), Mat(2, 64),
          Mat()};
  Rng rng(1);
  for (Index i = 0; i < s.starts.size(); ++i) s.starts(i) = rng.normal();
  s.second_moment = s.starts * s.starts.transpose() / static_cast<double>(s.starts.cols());
  return s;
}

Objective<Loss> objective(const Scene& s) {
  return {Loss{Sim::State::Zero(2)}, LossTiming::Continuous, 1.0,
          control_cost * s.problem.steps / 2.0};
}

Sim simulator(const Scene& s) { return Sim(s.problem.a, s.problem.b); }

/// The engine's update field of one flow mode, g(K) (flat, row-major K): g_R for Full, g_M for
/// PhysicsOnly.
Vec engine_field(const Scene& s, FlowMode mode, const Vec& flat) {
  const Sim sim = simulator(s);
  Feedback feedback(2, 1);
  feedback.params() = flat;
  Engine engine(sim, feedback, objective(s), s.problem.steps);
  engine.forward(s.starts);
  Vec g;
  engine.reverse(mode, g, 0);
  return g;
}

struct Row {
  long epoch;
  double distance, gap;                   ///< to K̄* and J(K̄*)
  double riccati_distance, riccati_gap;   ///< to the Riccati first gain K_0 and J_ric
};

/// The Riccati references of a setting: the first gain of the optimal sequence and its loss.
struct Riccati {
  Mat first_gain;
  double loss;
};

/// Trains from K = 0 and records the distances and relative loss gaps to both references at
/// `report_epochs`.
std::vector<Row> train(const Scene& s, Method method, const lqr::ConstantGainOptimum& best,
                       const Riccati& riccati, Mat* final_gain, bool* stopped) {
  const Sim sim = simulator(s);
  Feedback feedback(2, 1);
  TrainerOptions options;
  options.method = method;
  options.batch = s.starts.cols();
  Trainer trainer(sim, feedback, objective(s), s.problem.steps,
                  Adam<double>(AdamOptions<double>{0.01}), options);
  std::vector<Row> rows;
  *stopped = false;
  for (long epoch = 1; epoch <= epochs && !*stopped; ++epoch) {
    trainer.train_epoch(s.starts, s.starts);
    *stopped = trainer.stopped();
    if (std::find(report_epochs.begin(), report_epochs.end(), epoch) == report_epochs.end())
      continue;
    const Mat gain = feedback.gain();
    const double loss = lqr::constant_gain_loss(s.problem, gain, s.second_moment);
    rows.push_back({epoch, (gain - best.gain).norm(), (loss - best.loss) / best.loss,
                    (gain - riccati.first_gain).norm(), (loss - riccati.loss) / riccati.loss});
  }
  *final_gain = feedback.gain();
  return rows;
}

/// "‖K − K̄*‖, gap" as the summary table prints it.
std::string cell(double distance, double gap) {
  char text[64];
  std::snprintf(text, sizeof text, "%.2g, %.2g", distance, std::abs(gap) < 1e-15 ? 0.0 : gap);
  return text;
}

/// Prints the references and the training of one setting; returns its summary-table row.
std::string study(double radius, int steps) {
  const Scene s = make_scene(radius, steps);
  const auto ric = lqr::riccati(s.problem);
  const double ric_loss = lqr::optimal_loss(s.problem, s.second_moment);
  const auto best = lqr::optimal_constant_gain(s.problem, s.second_moment, ric.gains[0]);
  double m_residual = 0;
  const Mat fixed_m = lqr::unflatten(
      lqr::newton_root([&](const Vec& v, Vec& out) { out = engine_field(s, FlowMode::PhysicsOnly, v); },
                       lqr::flatten(best.gain), &m_residual),
      1, 2);
  const double fixed_m_loss = lqr::constant_gain_loss(s.problem, fixed_m, s.second_moment);

  std::printf("\n## spectral radius %.2f, horizon m = %d\n", radius, steps);
  std::printf("Riccati   K_0 = (%+.6f, %+.6f)  J_ric = %.8g\n", ric.gains[0](0, 0),
              ric.gains[0](0, 1), ric_loss);
  const double regular_at_best =
      engine_field(s, FlowMode::Full, lqr::flatten(best.gain)).norm();
  std::printf("constant  K*  = (%+.6f, %+.6f)  J*    = %.8g  (J*/J_ric - 1 = %.3g; |FD grad J| = "
              "%.1e, |g_R| = %.1e; min Hessian eigenvalue %.3g; |K* - K_0| = %.4f)\n",
              best.gain(0, 0), best.gain(0, 1), best.loss, best.loss / ric_loss - 1,
              best.gradient_norm, regular_at_best, best.min_hessian_eigenvalue,
              (best.gain - ric.gains[0]).norm());
  std::printf("M fixed   K_M = (%+.6f, %+.6f)  J(K_M) = %.8g  (J(K_M)/J* - 1 = %.3g; |K_M - K*| "
              "= %.4f; |g_M| = %.1e)\n",
              fixed_m(0, 0), fixed_m(0, 1), fixed_m_loss, fixed_m_loss / best.loss - 1,
              (fixed_m - best.gain).norm(), m_residual);
  std::printf("method | %s\n", "epoch: |K - K*|  (J - J*)/J*  [|K - K_0|  (J - J_ric)/J_ric]");
  char head[32];
  std::snprintf(head, sizeof head, "| %.1f | %d |", radius, steps);
  std::string summary = head;
  for (Method method : {Method::Regular, Method::Modified, Method::Combined}) {
    Mat final_gain;
    bool stopped = false;
    const auto rows = train(s, method, best, {ric.gains[0], ric_loss}, &final_gain, &stopped);
    std::printf("%-6s |", std::string(label(method)).c_str());
    for (const Row& r : rows)
      std::printf(" %ld: %.2e %.2e [%.2e %.2e] |", r.epoch, r.distance, r.gap, r.riccati_distance,
                  r.riccati_gap);
    if (stopped) std::printf(" stopped on a non-finite value");
    std::printf(" final |K - K_0| = %.2e, |K - K_M| = %.2e", (final_gain - ric.gains[0]).norm(),
                (final_gain - fixed_m).norm());
    if (method == Method::Combined) {  // where C rests, each component of g_C is zero
      const Vec g_r = engine_field(s, FlowMode::Full, lqr::flatten(final_gain));
      const Vec g_m = engine_field(s, FlowMode::PhysicsOnly, lqr::flatten(final_gain));
      std::printf("; there g_R = (%+.1e, %+.1e), g_M = (%+.1e, %+.1e)", g_r(0), g_r(1), g_m(0),
                  g_m(1));
    }
    std::printf("\n");
    summary.append(" ")
        .append(stopped ? std::string("stopped") : cell(rows.back().distance, rows.back().gap))
        .append(" |");
  }
  return summary.append(" ")
      .append(cell((fixed_m - best.gain).norm(), fixed_m_loss / best.loss - 1))
      .append(" |");
}

}  // namespace

int main(int argc, char** argv) {
  sbptt::examples::ignore_write_signals();
  if (argc == 2 && std::string_view(argv[1]) == "--help") {
    std::printf("usage: lqr_convergence\ncompares R, M and C with the Riccati optimum of a linear "
                "scene (docs/results.md); no options, about a minute\n");
    return sbptt::examples::with_streams_checked("lqr_convergence", 0);
  }
  if (argc > 1) {
    const char* unexpected = std::string_view(argv[1]) == "--help" ? argv[2] : argv[1];
    std::fprintf(stderr, "lqr_convergence: unexpected argument '%s'; the study takes no options "
                         "but --help alone\n", unexpected);
    return 2;
  }
  try {
    std::printf("# LQR convergence: d = 2, k = 1, A = s rot(0.3), B = (0,1), Q = I, R = %.2g, "
                "64 states, full batch, Adam lr 0.01, %ld epochs, double\n",
                control_cost, epochs);
    if (!sbptt::examples::streams_written("lqr_convergence")) return 1;
    std::vector<std::string> summary;
    for (double radius : {0.9, 1.0, 1.1})
      for (int steps : {5, 20, 50}) summary.push_back(study(radius, steps));
    std::printf("\n## Summary at epoch %ld: |K - K*|, (J - J*)/J* (a gap below 1e-15 printed as 0)"
                "\n\n| s | m | R | M | C | M's fixed point K_M |\n|---:|---:|---|---|---|---|\n",
                epochs);
    for (const auto& row : summary) std::printf("%s\n", row.c_str());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "lqr_convergence: %s\n", e.what());
    return 1;
  }
  return sbptt::examples::with_streams_checked("lqr_convergence", 0);
}
