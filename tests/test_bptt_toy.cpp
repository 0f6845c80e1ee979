// The paper's Fig. 1 toy problem: P(x, c) = x + c, c = θ1 x² + θ2 x (a user-defined
// controller), x_0 = −0.3, target 2, 4 steps, L = ½ (x_4 − 2)². Values: paper.md §3.1.
#include <catch2/catch.hpp>

#include <array>

#include "sbptt/bptt/engine.hpp"
#include "sbptt/bptt/losses.hpp"
#include "sbptt/optim/combined_update.hpp"
#include "sbptt/sim/linear.hpp"
#include "polynomial_policy.hpp"

using namespace sbptt;
using sbptt::testing::PolynomialPolicy;

namespace {

using Sim = LinearSystem<double, 1, 1>;
using Loss = SquaredDistanceLoss<Sim::State>;

struct Toy {
  Sim sim = Sim::scalar(1.0, 1.0);
  PolynomialPolicy<double> policy{{2, 1}};
  Engine<Sim, PolynomialPolicy<double>, Loss> engine{sim, policy, objective(), 4};

  static Objective<Loss> objective() {
    Sim::State target;
    target(0) = 2.0;
    return {Loss{target}, LossTiming::Final, 1.0, 0.0};
  }

  GradientPair<double> at(double theta1, double theta2) {
    policy.params() << theta1, theta2;
    return engine.regular_and_modified(Matrix<double>::Constant(1, 1, -0.3));
  }

  Vector<double> vector_at(double theta1, double theta2, FlowMode mode) {
    policy.params() << theta1, theta2;
    engine.forward(Matrix<double>::Constant(1, 1, -0.3));
    Vector<double> g;
    engine.reverse(mode, g);
    return g;
  }

  /// ∂v₂/∂θ1 − ∂v₁/∂θ2 of the field of `mode`, by central differences.
  double curl(double theta1, double theta2, FlowMode mode) {
    const double h = 1e-5;
    const double dv2 = (vector_at(theta1 + h, theta2, mode)(1) -
                        vector_at(theta1 - h, theta2, mode)(1)) / (2 * h);
    const double dv1 = (vector_at(theta1, theta2 + h, mode)(0) -
                        vector_at(theta1, theta2 - h, mode)(0)) / (2 * h);
    return dv2 - dv1;
  }
};

struct Row {
  std::array<double, 2> theta;
  double x4, loss;
  std::array<double, 2> regular, modified, combined;
};

// paper.md §3.1 (6 significant digits as printed there).
const Row table[] = {
    {{0, 0}, -0.3, 2.645, {-0.828, 2.76}, {-0.828, 2.76}, {-0.828, 2.76}},
    {{1, 1}, -0.996677, 4.49004, {-2.91843, 3.21987}, {-5.44069, 7.52841}, {-5.44069, 7.52841}},
    {{2, -1}, 1.41055e-4, 1.99972, {-2.11568e-3, -2.05214e-2}, {-0.253321, 0.0935972},
     {-0.253321, 0}},
    {{-1, 2}, -836.06, 351173, {-2.14442e6, 1.5287e6}, {-645619, 27399.3}, {-645619, 27399.3}},
    {{0.5, 1.5}, -3.11535, 13.0834, {-33.5321, 11.5521}, {-50.35, 26.3844}, {-50.35, 26.3844}},
    {{-3, -3}, -0.797645, 3.91341, {-2.47227, -48.7552}, {-5.79088, 5.3268}, {-5.79088, 0}},
};

}  // namespace

TEST_CASE("toy: g_R, g_M and g_C match the table of paper.md §3.1", "[bptt][toy]") {
  Toy toy;
  for (const Row& row : table) {
    INFO("theta = (" << row.theta[0] << ", " << row.theta[1] << ")");
    const auto pair = toy.at(row.theta[0], row.theta[1]);
    CHECK(toy.engine.trajectory().states[4](0, 0) == Approx(row.x4).epsilon(1e-5));
    CHECK(pair.loss == Approx(row.loss).epsilon(1e-5));
    Vector<double> combined;
    combine(pair.modified, pair.regular, combined);
    for (Index i = 0; i < 2; ++i) {
      const auto k = static_cast<std::size_t>(i);
      CHECK(pair.regular(i) == Approx(row.regular[k]).epsilon(1e-5));
      CHECK(pair.modified(i) == Approx(row.modified[k]).epsilon(1e-5));
      CHECK(combined(i) == Approx(row.combined[k]).epsilon(1e-5));
    }
  }
}

TEST_CASE("toy: the regular gradient equals finite differences of the loss", "[bptt][toy]") {
  Toy toy;
  const double h = 1e-6;
  for (const Row& row : table) {
    const auto pair = toy.at(row.theta[0], row.theta[1]);
    for (Index i = 0; i < 2; ++i) {
      std::array<double, 2> plus = row.theta, minus = row.theta;
      plus[static_cast<std::size_t>(i)] += h;
      minus[static_cast<std::size_t>(i)] -= h;
      const double fd = (toy.at(plus[0], plus[1]).loss - toy.at(minus[0], minus[1]).loss) / (2 * h);
      CHECK(pair.regular(i) == Approx(fd).epsilon(1e-6));
    }
  }
}

TEST_CASE("toy: with P_x = 1, g_M = (x_4 − y) Σ_n ∂c_n/∂θ and g_S is the last step's term",
          "[bptt][toy]") {
  Toy toy;
  const auto pair = toy.at(0.5, 1.5);
  const auto& states = toy.engine.trajectory().states;
  const double residual = states[4](0, 0) - 2.0;
  double sum_x2 = 0, sum_x = 0;
  for (int n = 0; n < 4; ++n) {
    const double x = states[static_cast<std::size_t>(n)](0, 0);
    sum_x2 += x * x;
    sum_x += x;
  }
  CHECK(pair.modified(0) == Approx(residual * sum_x2).epsilon(1e-13));
  CHECK(pair.modified(1) == Approx(residual * sum_x).epsilon(1e-13));

  const auto stopped = toy.vector_at(0.5, 1.5, FlowMode::Stopped);
  const double x3 = states[3](0, 0);
  CHECK(stopped(0) == Approx(residual * x3 * x3).epsilon(1e-13));
  CHECK(stopped(1) == Approx(residual * x3).epsilon(1e-13));
}

TEST_CASE("toy: NetworkOnly keeps only the network path, g_N = r Σ_n ∂c_n/∂θ Π_{k>n} K_k",
          "[bptt][toy]") {
  // Without the physics term A = 1, the adjoint of x_n is carried back by the controller's
  // input Jacobian alone: λ_n = K_n μ_n, μ_n = λ_{n+1}, K_n = 2θ1 x_n + θ2.
  Toy toy;
  for (const Row& row : table) {
    const double t1 = row.theta[0], t2 = row.theta[1];
    const auto network = toy.vector_at(t1, t2, FlowMode::NetworkOnly);
    const auto& states = toy.engine.trajectory().states;
    double carried = states[4](0, 0) - 2.0;  // r, then r Π_{k>n} K_k
    double g1 = 0, g2 = 0;
    for (int n = 3; n >= 0; --n) {
      const double x = states[static_cast<std::size_t>(n)](0, 0);
      g1 += carried * x * x;
      g2 += carried * x;
      carried *= 2 * t1 * x + t2;
    }
    INFO("theta = (" << t1 << ", " << t2 << ")");
    CHECK(network(0) == Approx(g1).epsilon(1e-13));
    CHECK(network(1) == Approx(g2).epsilon(1e-13));
  }
}

TEST_CASE("toy: the modified field has curl, the gradient field has none", "[bptt][toy]") {
  Toy toy;
  CHECK(toy.curl(0, 0, FlowMode::PhysicsOnly) == Approx(1.242).epsilon(1e-3));
  CHECK(toy.curl(1, 1, FlowMode::PhysicsOnly) == Approx(7.010).epsilon(1e-3));
  CHECK(toy.curl(0.5, 0.5, FlowMode::PhysicsOnly) == Approx(4.794).epsilon(1e-3));
  CHECK(toy.curl(2, -1, FlowMode::PhysicsOnly) == Approx(-0.658).epsilon(1e-3));
  for (const Row& row : table)
    CHECK(std::abs(toy.curl(row.theta[0], row.theta[1], FlowMode::Full)) <
          1e-6 * (1 + toy.vector_at(row.theta[0], row.theta[1], FlowMode::Full).norm()));
}

namespace {
/// The toy's controller, counting its forward calls (one per step and batch).
class CountingPolicy : public PolynomialPolicy<double> {
public:
  using PolynomialPolicy<double>::PolynomialPolicy;
  void forward(const Matrix<double>& x, Matrix<double>& y, Workspace& ws) const {
    ++forward_calls;
    PolynomialPolicy<double>::forward(x, y, ws);
  }
  mutable int forward_calls = 0;
};
}  // namespace

TEST_CASE("toy: one forward pass serves both sweeps", "[bptt][toy]") {
  CountingPolicy counting{{2, 1}};
  counting.params() << 1, 1;
  const Sim sim = Sim::scalar(1.0, 1.0);
  Engine<Sim, CountingPolicy, Loss> counted{sim, counting, Toy::objective(), 4};
  counted.regular_and_modified(Matrix<double>::Constant(1, 1, -0.3));
  CHECK(counting.forward_calls == 4);  // 4 steps, one rollout

  Toy toy;
  const auto pair = toy.at(1, 1);
  CHECK(pair.regular.isApprox(toy.vector_at(1, 1, FlowMode::Full), 1e-15));
  CHECK(pair.modified.isApprox(toy.vector_at(1, 1, FlowMode::PhysicsOnly), 1e-15));
  CHECK(pair.comparison.cos_modified_regular ==
        Approx(pair.modified.dot(pair.regular) / (pair.modified.norm() * pair.regular.norm())));
  CHECK(pair.comparison.agree_fraction == 1.0);
  CHECK(toy.at(2, -1).comparison.agree_fraction == 0.5);
}
