// The paper's Fig. 1 toy problem: P(x, c) = x + c, c = θ1 x² + θ2 x (a user-defined
// controller), x_0 = −0.3, target 2, 4 steps, L = ½ (x_4 − 2)². Values: docs/paper.md §3.1.
#include <catch2/catch.hpp>

#include <array>
#include <type_traits>

#include "sbptt/bptt/engine.hpp"
#include "sbptt/bptt/losses.hpp"
#include "sbptt/optim/combined_update.hpp"
#include "sbptt/sim/linear.hpp"
#include "polynomial_policy.hpp"

using namespace sbptt;
using sbptt::testing::PolynomialPolicy;

namespace {

template <class Scalar>
using Sim = LinearSystem<Scalar, 1, 1>;
template <class Scalar>
using Loss = SquaredDistanceLoss<typename Sim<Scalar>::State>;

/// Relative tolerance for checks that are exact up to round-off in `Scalar`.
template <class Scalar>
constexpr double round_off = std::is_same_v<Scalar, float> ? 1e-5 : 1e-13;

template <class Scalar = double>
struct Toy {
  Sim<Scalar> sim = Sim<Scalar>::scalar(1, 1);
  PolynomialPolicy<Scalar> policy{{2, 1}};
  Engine<Sim<Scalar>, PolynomialPolicy<Scalar>, Loss<Scalar>> engine{sim, policy, objective(), 4};

  static Objective<Loss<Scalar>> objective() {
    typename Sim<Scalar>::State target;
    target(0) = 2;
    return {Loss<Scalar>{target}, LossTiming::Final, 1, 0};
  }

  GradientPair<Scalar> at(double theta1, double theta2) {
    policy.params() << static_cast<Scalar>(theta1), static_cast<Scalar>(theta2);
    return engine.regular_and_modified(Matrix<Scalar>::Constant(1, 1, Scalar(-0.3)));
  }

  Vector<Scalar> vector_at(double theta1, double theta2, FlowMode mode) {
    policy.params() << static_cast<Scalar>(theta1), static_cast<Scalar>(theta2);
    engine.forward(Matrix<Scalar>::Constant(1, 1, Scalar(-0.3)));
    Vector<Scalar> g;
    engine.reverse(mode, g);
    return g;
  }

  [[nodiscard]] double state(int n) const {
    return static_cast<double>(engine.trajectory().states[static_cast<std::size_t>(n)](0, 0));
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

/// Σ_n r Π_{k>n} κ_k ∂c_n/∂θ with ∂c_n/∂θ = (x_n², x_n): the adjoint r = x_4 − y carried back
/// by κ_k, the factor of the mode (1 + K_k for Full, K_k for NetworkOnly), K_k = 2θ1 x_k + θ2.
template <class Scalar, class Kappa>
std::array<double, 2> carried_sum(const Toy<Scalar>& toy, Kappa kappa) {
  double carried = toy.state(4) - 2.0;
  std::array<double, 2> g{0, 0};
  for (int n = 3; n >= 0; --n) {
    const double x = toy.state(n);
    g[0] += carried * x * x;
    g[1] += carried * x;
    carried *= kappa(x);
  }
  return g;
}

struct Row {
  std::array<double, 2> theta;
  double x4, loss;
  std::array<double, 2> regular, modified, combined;
};

// docs/paper.md §3.1 (6 significant digits as printed there).
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

TEMPLATE_TEST_CASE("toy: g_R, g_M and g_C match the table of docs/paper.md §3.1", "[bptt][toy]", float,
                   double) {
  Toy<TestType> toy;
  for (const Row& row : table) {
    INFO("theta = (" << row.theta[0] << ", " << row.theta[1] << ")");
    const auto pair = toy.at(row.theta[0], row.theta[1]);
    CHECK(toy.state(4) == Approx(row.x4).epsilon(1e-5));
    CHECK(pair.loss == Approx(row.loss).epsilon(1e-5));
    Vector<TestType> combined;
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
  Toy<> toy;
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

TEMPLATE_TEST_CASE("toy: with P_x = 1, g_M = (x_4 − y) Σ_n ∂c_n/∂θ and g_S is the last step's "
                   "term", "[bptt][toy]", float, double) {
  Toy<TestType> toy;
  const auto pair = toy.at(0.5, 1.5);
  const double residual = toy.state(4) - 2.0;
  double sum_x2 = 0, sum_x = 0;
  for (int n = 0; n < 4; ++n) {
    sum_x2 += toy.state(n) * toy.state(n);
    sum_x += toy.state(n);
  }
  const double tolerance = round_off<TestType>;
  CHECK(pair.modified(0) == Approx(residual * sum_x2).epsilon(tolerance));
  CHECK(pair.modified(1) == Approx(residual * sum_x).epsilon(tolerance));

  const auto stopped = toy.vector_at(0.5, 1.5, FlowMode::Stopped);
  const double x3 = toy.state(3);
  CHECK(stopped(0) == Approx(residual * x3 * x3).epsilon(tolerance));
  CHECK(stopped(1) == Approx(residual * x3).epsilon(tolerance));
}

TEMPLATE_TEST_CASE("toy: Full carries the adjoint by 1 + K_k, NetworkOnly by K_k alone, "
                   "g = r Σ_n ∂c_n/∂θ Π_{k>n} κ_k", "[bptt][toy]", float, double) {
  // The physics Jacobian of P(x, c) = x + c is 1 in both arguments, so the step's total
  // derivative is 1 + K_k; without the physics term only the controller's K_k remains.
  Toy<TestType> toy;
  for (const Row& row : table) {
    const double t1 = row.theta[0], t2 = row.theta[1];
    auto input_jacobian = [&](double x) { return 2 * t1 * x + t2; };
    INFO("theta = (" << t1 << ", " << t2 << ")");
    const auto network = toy.vector_at(t1, t2, FlowMode::NetworkOnly);
    const auto g_n = carried_sum(toy, input_jacobian);
    const auto full = toy.vector_at(t1, t2, FlowMode::Full);
    const auto g_r = carried_sum(toy, [&](double x) { return 1 + input_jacobian(x); });
    // Full's terms cancel at θ = (2, −1); the margin is round-off of the largest term there.
    const double margin = round_off<TestType> * 10;
    for (Index i = 0; i < 2; ++i) {
      const auto k = static_cast<std::size_t>(i);
      CHECK(network(i) == Approx(g_n[k]).epsilon(round_off<TestType>));
      CHECK(full(i) == Approx(g_r[k]).epsilon(round_off<TestType>).margin(margin));
    }
  }
}

TEST_CASE("toy: the modified field has curl, the gradient field has none", "[bptt][toy]") {
  Toy<> toy;
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
  const auto sim = Sim<double>::scalar(1.0, 1.0);
  Engine<Sim<double>, CountingPolicy, Loss<double>> counted{sim, counting, Toy<>::objective(), 4};
  counted.regular_and_modified(Matrix<double>::Constant(1, 1, -0.3));
  CHECK(counting.forward_calls == 4);  // 4 steps, one rollout

  Toy<> toy;
  const auto pair = toy.at(1, 1);
  CHECK(pair.regular.isApprox(toy.vector_at(1, 1, FlowMode::Full), 1e-15));
  CHECK(pair.modified.isApprox(toy.vector_at(1, 1, FlowMode::PhysicsOnly), 1e-15));
  CHECK(pair.comparison.cos_modified_regular ==
        Approx(pair.modified.dot(pair.regular) / (pair.modified.norm() * pair.regular.norm())));
  CHECK(pair.comparison.agree_fraction == 1.0);
  CHECK(toy.at(2, -1).comparison.agree_fraction == 0.5);
}
