// The engine on x' = a x + b c with the linear policy c = θ x, against closed forms.
//
// x_n = ρⁿ x_0 with ρ = a + bθ. The factor that carries λ_{n+1} into λ_n is κ_n: a + bθ (Full),
// a (PhysicsOnly), bθ (NetworkOnly), 0 (Stopped, or a truncation cut). Expanding the
// recursion gives, for the batch mean of Σ_{j∈S} w·½(x_j − y)²,
//     g = (1/B) Σ_b Σ_{j∈S} w (x_j − y) Σ_{n<j} b x_n Π_{i=n+1}^{j-1} κ_i
// and for a uniform Full schedule with a final loss, g = (x_m − y) m ρ^{m-1} b x_0 (mean).
#include <catch2/catch.hpp>

#include <cmath>
#include <limits>
#include <stdexcept>
#include <type_traits>
#include <vector>

#include "sbptt/bptt/engine.hpp"
#include "sbptt/bptt/losses.hpp"
#include "sbptt/core/rng.hpp"
#include "sbptt/nn/network.hpp"
#include "sbptt/sim/linear.hpp"
#include "polynomial_policy.hpp"

using namespace sbptt;
using sbptt::testing::PolynomialPolicy;

namespace {

template <class Scalar>
using Sim = LinearSystem<Scalar, 1, 1>;
template <class Scalar>
using Loss = SquaredDistanceLoss<typename Sim<Scalar>::State>;

struct Setup {
  double a = 0.9, b = 0.5, theta = -0.7, target = 0.4;
  int steps = 6;
  LossTiming timing = LossTiming::Final;
  double weight = 1.0;
  std::vector<double> initial{0.3, -1.2, 2.0};
};

double kappa(const Setup& s, FlowMode mode) {
  switch (mode) {
    case FlowMode::Full: return s.a + s.b * s.theta;
    case FlowMode::PhysicsOnly: return s.a;
    case FlowMode::NetworkOnly: return s.b * s.theta;
    case FlowMode::Stopped: return 0.0;
  }
  return 0.0;
}

/// The expanded-sum closed form of the file comment.
double closed_form(const Setup& s, const std::vector<FlowMode>& modes, int truncation) {
  const double rho = s.a + s.b * s.theta;
  double g = 0;
  for (double x0 : s.initial) {
    auto x = [&](int n) { return std::pow(rho, n) * x0; };
    const int first = s.timing == LossTiming::Final ? s.steps : 1;
    for (int j = first; j <= s.steps; ++j) {
      const double residual = s.weight * (x(j) - s.target);
      for (int n = 0; n < j; ++n) {
        double product = 1;
        for (int i = n + 1; i <= j - 1; ++i) {
          const bool cut = truncation > 0 && i % truncation == 0;
          product *= cut ? 0.0 : kappa(s, modes[static_cast<std::size_t>(i)]);
        }
        g += residual * s.b * x(n) * product;
      }
    }
  }
  return g / static_cast<double>(s.initial.size());
}

template <class Scalar>
Scalar engine_gradient(const Setup& s, const FlowSchedule& schedule, int truncation,
                       Scalar* loss = nullptr, double control_weight = 0) {
  const auto sim = Sim<Scalar>::scalar(static_cast<Scalar>(s.a), static_cast<Scalar>(s.b));
  PolynomialPolicy<Scalar> policy({1});
  policy.params()(0) = static_cast<Scalar>(s.theta);
  typename Sim<Scalar>::State target;
  target(0) = static_cast<Scalar>(s.target);
  Objective<Loss<Scalar>> objective{Loss<Scalar>{target}, s.timing, s.weight, control_weight};
  Engine engine(sim, policy, objective, s.steps);
  Matrix<Scalar> x0(1, static_cast<Index>(s.initial.size()));
  for (std::size_t i = 0; i < s.initial.size(); ++i)
    x0(0, static_cast<Index>(i)) = static_cast<Scalar>(s.initial[i]);
  const Scalar l = engine.forward(x0);
  if (loss) *loss = l;
  Vector<Scalar> g;
  engine.reverse(schedule, g, truncation);
  return g(0);
}

const std::vector<FlowMode> all_modes{FlowMode::Full, FlowMode::PhysicsOnly,
                                      FlowMode::NetworkOnly, FlowMode::Stopped};

}  // namespace

TEST_CASE("linear system: Full gradient equals the product-rule closed form", "[bptt]") {
  for (int m = 1; m <= 8; ++m) {
    Setup s;
    s.steps = m;
    const double rho = s.a + s.b * s.theta;
    double expected = 0;
    for (double x0 : s.initial)
      expected += (std::pow(rho, m) * x0 - s.target) * m * std::pow(rho, m - 1) * s.b * x0;
    expected /= static_cast<double>(s.initial.size());
    CHECK(engine_gradient<double>(s, FlowMode::Full, 0) == Approx(expected).epsilon(1e-13));
  }
}

/// Relative tolerance and absolute margin of a closed-form comparison in `Scalar`.
template <class Scalar>
constexpr double closed_form_tolerance = std::is_same_v<Scalar, float> ? 1e-5 : 1e-12;
template <class Scalar>
constexpr double closed_form_margin = std::is_same_v<Scalar, float> ? 1e-6 : 1e-15;

TEMPLATE_TEST_CASE("linear system: every mode equals its closed form, final and continuous",
                   "[bptt]", float, double) {
  const double tolerance = closed_form_tolerance<TestType>, margin = closed_form_margin<TestType>;
  for (auto timing : {LossTiming::Final, LossTiming::Continuous}) {
    for (FlowMode mode : all_modes) {
      for (int m : {1, 2, 5, 8}) {
        Setup s;
        s.steps = m;
        s.timing = timing;
        s.weight = timing == LossTiming::Final ? 1.0 : 1.0 / m;
        const std::vector<FlowMode> modes(static_cast<std::size_t>(m), mode);
        INFO("mode " << label(mode) << ", steps " << m);
        CHECK(static_cast<double>(engine_gradient<TestType>(s, mode, 0)) ==
              Approx(closed_form(s, modes, 0)).epsilon(tolerance).margin(margin));
      }
    }
  }
}

TEMPLATE_TEST_CASE("linear system: per-step schedules and truncation windows", "[bptt]", float,
                   double) {
  const double tolerance = closed_form_tolerance<TestType>, margin = closed_form_margin<TestType>;
  Rng rng(7);
  for (int trial = 0; trial < 40; ++trial) {
    Setup s;
    s.steps = 8;
    s.timing = trial % 2 ? LossTiming::Continuous : LossTiming::Final;
    s.theta = rng.uniform(-1.5, 1.5);
    std::vector<FlowMode> modes;
    for (int n = 0; n < s.steps; ++n)
      modes.push_back(all_modes[static_cast<std::size_t>(rng.uniform(0, 4))]);
    const int truncation = trial % 4;  // 0 = none
    INFO("trial " << trial << ", truncation " << truncation);
    CHECK(static_cast<double>(engine_gradient<TestType>(s, FlowSchedule(modes), truncation)) ==
          Approx(closed_form(s, modes, truncation)).epsilon(tolerance).margin(margin));
  }
}

TEST_CASE("truncation: window 1 equals Stopped, a window >= horizon equals no truncation",
          "[bptt]") {
  Setup s;
  s.steps = 7;
  s.timing = LossTiming::Continuous;
  CHECK(engine_gradient<double>(s, FlowMode::Full, 1) ==
        Approx(engine_gradient<double>(s, FlowMode::Stopped, 0)).epsilon(1e-14));
  CHECK(engine_gradient<double>(s, FlowMode::Full, 7) ==
        Approx(engine_gradient<double>(s, FlowMode::Full, 0)).epsilon(1e-14));
}

TEST_CASE("linear system: Full gradient with a control regulariser equals finite differences",
          "[bptt]") {
  Setup s;
  s.timing = LossTiming::Continuous;
  s.weight = 1.0 / s.steps;
  const double rc = 0.3;
  const double h = 1e-5;
  auto loss_at = [&](double theta) {
    Setup p = s;
    p.theta = theta;
    double l = 0;
    engine_gradient<double>(p, FlowMode::Full, 0, &l, rc);
    return l;
  };
  const double fd = (loss_at(s.theta + h) - loss_at(s.theta - h)) / (2 * h);
  CHECK(engine_gradient<double>(s, FlowMode::Full, 0, nullptr, rc) == Approx(fd).epsilon(1e-8));

  // With the network path stopped, the regulariser adds only its direct term
  // Σ_n 2ρ/m · c_n · x_n (batch mean), c_n = θ x_n.
  const double rho = s.a + s.b * s.theta;
  double direct = 0;
  for (double x0 : s.initial)
    for (int n = 0; n < s.steps; ++n)
      direct += 2 * rc / s.steps * s.theta * std::pow(rho, 2 * n) * x0 * x0;
  direct /= static_cast<double>(s.initial.size());
  const std::vector<FlowMode> modified(static_cast<std::size_t>(s.steps), FlowMode::PhysicsOnly);
  CHECK(engine_gradient<double>(s, FlowMode::PhysicsOnly, 0, nullptr, rc) ==
        Approx(closed_form(s, modified, 0) + direct).epsilon(1e-12));
}

TEST_CASE("engine diagnostics: adjoint norms follow |κ|^(m-n), and non-finite values are located",
          "[bptt]") {
  Setup s;
  s.steps = 5;
  s.initial = {1.0};
  const auto sim = Sim<double>::scalar(s.a, s.b);
  PolynomialPolicy<double> policy({1});
  policy.params()(0) = s.theta;
  Sim<double>::State target;
  target(0) = s.target;
  Engine engine(sim, policy, Objective<Loss<double>>{Loss<double>{target}}, s.steps);
  Matrix<double> x0 = Matrix<double>::Ones(1, 1);
  engine.forward(x0);
  Vector<double> g;
  for (FlowMode mode : {FlowMode::Full, FlowMode::PhysicsOnly}) {
    const auto& d = engine.reverse(mode, g);
    const double lambda_m = std::abs(std::pow(s.a + s.b * s.theta, s.steps) - s.target);
    for (int n = 0; n <= s.steps; ++n)
      CHECK(d.adjoint_norms[static_cast<std::size_t>(n)] ==
            Approx(lambda_m * std::pow(std::abs(kappa(s, mode)), s.steps - n)));
    CHECK(d.grad_norm2 == Approx(g.squaredNorm()));
    CHECK_FALSE(d.first_non_finite);
  }

  // A sweep's report: an adjoint whose square overflows is finite and not reported; the first
  // NaN is, at its step and sample, whichever came before it; the gradient's NaN likewise.
  detail::SweepBuffers<double, int> sweep;
  sweep.begin(1, 1, 3, 4, false);
  sweep.lambda << 1.0, std::numeric_limits<double>::max(), 2.0;
  sweep.record_adjoint(4);
  CHECK(std::isinf(sweep.diagnostics.adjoint_norms[4]));
  CHECK_FALSE(sweep.diagnostics.first_non_finite);
  sweep.lambda << 1.0, 2.0, -std::numeric_limits<double>::infinity();
  sweep.record_adjoint(3);
  REQUIRE(sweep.diagnostics.first_non_finite);
  CHECK(sweep.diagnostics.first_non_finite->quantity == Quantity::Adjoint);
  CHECK(sweep.diagnostics.first_non_finite->step == 3);
  CHECK(sweep.diagnostics.first_non_finite->sample == 2);
  sweep.lambda << std::nan(""), 0.0, 0.0;
  sweep.record_adjoint(2);
  CHECK(sweep.diagnostics.first_non_finite->step == 3);
  sweep.begin(1, 1, 3, 4, false);
  sweep.lambda.setOnes();
  Vector<double> gradient(4);
  gradient << 0.0, 1.0, std::nan(""), 1e300;
  sweep.end(gradient);
  REQUIRE(sweep.diagnostics.first_non_finite);
  CHECK(sweep.diagnostics.first_non_finite->quantity == Quantity::Gradient);
  CHECK(sweep.diagnostics.first_non_finite->sample == 2);
  gradient(2) = 1e300;
  sweep.begin(1, 1, 3, 4, false);
  sweep.end(gradient);
  CHECK(std::isinf(sweep.diagnostics.grad_norm2));
  CHECK_FALSE(sweep.diagnostics.first_non_finite);

  Matrix<double> bad(1, 3);
  bad << 1.0, std::nan(""), 2.0;
  engine.forward(bad);
  REQUIRE(engine.forward_non_finite());
  CHECK(engine.forward_non_finite()->quantity == Quantity::State);
  CHECK(engine.forward_non_finite()->step == 0);
  CHECK(engine.forward_non_finite()->sample == 1);
}

TEST_CASE("engine rejects mismatched sizes and bad settings with a clear message", "[bptt]") {
  const auto sim = Sim<double>::scalar(1.0, 1.0);
  PolynomialPolicy<double> policy({1});
  Sim<double>::State target = Sim<double>::State::Zero();
  using Obj = Objective<Loss<double>>;
  REQUIRE_THROWS_WITH((Engine(sim, policy, Obj{Loss<double>{target}}, 0)),
                      Catch::Contains("steps = 0"));
  REQUIRE_THROWS_WITH(
      (Engine(sim, policy, Obj{Loss<double>{target}, LossTiming::Final, 1.0, -1.0}, 3)),
      Catch::Contains("control_weight = -1"));
  Engine engine(sim, policy, Obj{Loss<double>{target}}, 3);
  Vector<double> g;
  REQUIRE_THROWS_WITH(engine.reverse(FlowMode::Full, g), Catch::Contains("call forward first"));
  REQUIRE_THROWS_WITH(engine.forward(Matrix<double>::Zero(2, 4)),
                      Catch::Contains("2 rows") && Catch::Contains("state_dim = 1"));
  engine.forward(Matrix<double>::Ones(1, 2));
  REQUIRE_THROWS_WITH(engine.reverse(FlowSchedule({FlowMode::Full, FlowMode::Stopped}), g),
                      Catch::Contains("2 per-step modes for a horizon of 3"));
}

TEST_CASE("evaluate gives the forward loss without storing the trajectory", "[bptt]") {
  for (auto timing : {LossTiming::Final, LossTiming::Continuous}) {
    const auto sim = Sim<double>::scalar(0.9, 0.5);
    PolynomialPolicy<double> policy({1});
    policy.params()(0) = -0.7;
    Sim<double>::State target = Sim<double>::State::Constant(0.4);
    Engine engine(sim, policy, Objective<Loss<double>>{Loss<double>{target}, timing, 0.25, 0.3}, 6);
    Matrix<double> x0(1, 3);
    x0 << 0.3, -1.2, 2.0;
    const double stored = engine.forward(x0);
    // Closed form: Σ_{j∈S} w ½(ρʲx0 − y)² + ρ_reg/m Σ_n (θ ρⁿ x0)², batch mean.
    const double rho = 0.9 + 0.5 * -0.7;
    double expected = 0;
    for (Index b = 0; b < 3; ++b) {
      for (int n = 0; n <= 6; ++n) {
        const double x = std::pow(rho, n) * x0(0, b);
        const bool scored = timing == LossTiming::Final ? n == 6 : n >= 1;
        if (scored) expected += 0.25 * 0.5 * (x - 0.4) * (x - 0.4);
        if (n < 6) expected += 0.3 / 6 * (-0.7 * x) * (-0.7 * x);
      }
    }
    expected /= 3;
    CHECK(stored == Approx(expected).epsilon(1e-14));
    CHECK(engine.evaluate(x0) == Approx(expected).epsilon(1e-14));
  }
}

TEST_CASE("evaluate reports a non-finite initial state where forward does", "[bptt]") {
  const auto sim = Sim<double>::scalar(0.9, 0.5);
  PolynomialPolicy<double> policy({1});
  policy.params()(0) = -0.7;
  Engine engine(sim, policy, Objective<Loss<double>>{Loss<double>{Sim<double>::State::Zero()}}, 4);
  Matrix<double> bad(1, 3);
  bad << 1.0, std::numeric_limits<double>::infinity(), 2.0;
  engine.forward(bad);
  REQUIRE(engine.forward_non_finite());
  const NonFinite from_forward = *engine.forward_non_finite();
  engine.evaluate(bad);
  REQUIRE(engine.forward_non_finite());
  CHECK(engine.forward_non_finite()->quantity == from_forward.quantity);
  CHECK(engine.forward_non_finite()->step == from_forward.step);
  CHECK(engine.forward_non_finite()->sample == from_forward.sample);
  CHECK(engine.forward_non_finite()->quantity == Quantity::State);
  CHECK(engine.forward_non_finite()->step == 0);
  CHECK(engine.forward_non_finite()->sample == 1);
}

namespace {

/// x' = a x + b u that throws when a state exceeds `limit`: a user's step failing mid-rollout.
struct ThrowsAbove : Sim<double> {
  double limit = 0;
  void step(const State& x, const Control& u, State& x_next) const {
    if (x(0) > limit) throw std::runtime_error("ThrowsAbove: the state left the model's range");
    Sim<double>::step(x, u, x_next);
  }
};

}  // namespace

TEST_CASE("a forward pass that throws leaves no trajectory for a sweep", "[bptt]") {
  const ThrowsAbove sim{Sim<double>::scalar(2.0, 0.5), 5.0};
  PolynomialPolicy<double> policy({1});
  Engine engine(sim, policy, Objective<Loss<double>>{Loss<double>{Sim<double>::State::Zero()}}, 5);
  Vector<double> g;
  engine.forward(Matrix<double>::Constant(1, 2, 0.1));  // x_n = 0.1·2ⁿ stays below 5
  engine.reverse(FlowMode::Full, g);
  REQUIRE_THROWS_WITH(engine.forward(Matrix<double>::Ones(1, 2)),  // 1, 2, 4, 8: throws at step 3
                      Catch::Contains("left the model's range"));
  REQUIRE_THROWS_WITH(engine.reverse(FlowMode::Full, g), Catch::Contains("call forward first"));
  GradientPair<double> pair;
  REQUIRE_THROWS_WITH(engine.regular_and_modified(Matrix<double>::Ones(1, 2), pair),
                      Catch::Contains("left the model's range"));
  REQUIRE_THROWS_WITH(engine.reverse(FlowMode::Full, g), Catch::Contains("call forward first"));
  engine.forward(Matrix<double>::Constant(1, 2, 0.1));  // a finished pass can be swept again
  engine.reverse(FlowMode::Full, g);
}

TEST_CASE("a timed engine's first batch at a size stays untimed when the forward pass before it "
          "threw", "[bptt][threads]") {
  // The first finished batch of a size runs on the threads out of the schedule (it sizes their
  // buffers); a rollout that threw finished nothing, so the batch after it is still the first.
  const ThrowsAbove sim{Sim<double>::scalar(2.0, 0.5), 5.0};
  PolynomialPolicy<double> policy({1});
  Engine engine(sim, policy, Objective<Loss<double>>{Loss<double>{Sim<double>::State::Zero()}}, 5);
  engine.set_threads(2, 0.0, SweepThreading::Timed);  // every per-sample loop split once timed
  Vector<double> g;
  auto batch = [&](Index samples) {
    engine.forward(Matrix<double>::Constant(1, samples, 0.1));
    engine.reverse(FlowMode::Full, g);
  };
  batch(3);  // times the loops; until then no batch is the decision's
  REQUIRE(engine.sweep_tally().threaded + engine.sweep_tally().alone == 0);
  REQUIRE_THROWS_WITH(engine.forward(Matrix<double>::Ones(1, 2)),
                      Catch::Contains("left the model's range"));
  constexpr int probes = detail::SweepThreadingDecision::probes;
  for (int k = 0; k < 1 + probes; ++k) batch(2);
  CHECK(engine.sweep_tally().threaded == 1 + probes);  // the first, the threaded probes
  CHECK(engine.sweep_tally().alone == 0);
  for (int k = 0; k < probes; ++k) batch(2);
  CHECK(engine.sweep_tally().alone == probes);  // the probes alone
}

TEST_CASE("a squared-distance target of another size than the state is refused when the engine "
          "is built", "[bptt]") {
  const LinearSystem<double> sim(Eigen::MatrixXd::Identity(3, 3), Eigen::MatrixXd::Ones(3, 1));
  const auto policy = Network<double>::mlp(3, {4}, 1);  // parameters zero: every control is 0
  using DynamicLoss = SquaredDistanceLoss<Eigen::VectorXd>;
  const Objective<DynamicLoss> objective{DynamicLoss{Eigen::VectorXd::Zero(2)}};
  REQUIRE_THROWS_AS((Engine(sim, policy, objective, 4)), InvalidArgument);
  REQUIRE_THROWS_WITH((Engine(sim, policy, objective, 4)),
                      Catch::Contains("target has 2 entries") &&
                          Catch::Contains("state_dim = 3"));
  Engine fits(sim, policy, Objective<DynamicLoss>{DynamicLoss{Eigen::VectorXd::Zero(3)}}, 4);
  CHECK(fits.forward(Matrix<double>::Ones(3, 2)) == 1.5);  // x stays (1, 1, 1): ½‖x‖²
}

TEST_CASE("LinearSystem with dynamic sizes refuses inputs and adjoints of another size", "[sim]") {
  Eigen::MatrixXd a(2, 2), b(2, 1);
  a << 0.9, 0.2, -0.1, 1.1;
  b << 0.5, 2.0;
  const LinearSystem<double> sim(a, b);
  Eigen::VectorXd next, lambda_x, lambda_u;
  CHECK_THROWS_WITH(sim.step(Eigen::VectorXd::Zero(3), Eigen::VectorXd::Zero(1), next),
                    Catch::Contains("LinearSystem: x has size 3"));
  CHECK_THROWS_WITH(sim.vjp(Eigen::VectorXd::Zero(2), Eigen::VectorXd::Zero(1),
                            Eigen::VectorXd::Ones(3), &lambda_x, &lambda_u),
                    Catch::Contains("LinearSystem: lambda has size 3") &&
                        Catch::Contains("state_dim() = 2"));
  Eigen::VectorXd lambda(2);
  lambda << 1.0, -2.0;
  sim.vjp(Eigen::VectorXd::Zero(2), Eigen::VectorXd::Zero(1), lambda, &lambda_x, &lambda_u);
  CHECK(lambda_x(0) == Approx(0.9 * 1.0 - 0.1 * -2.0));  // Aᵀλ
  CHECK(lambda_x(1) == Approx(0.2 * 1.0 + 1.1 * -2.0));
  CHECK(lambda_u(0) == Approx(0.5 * 1.0 + 2.0 * -2.0));  // Bᵀλ
}
