// The simulator checker must catch what it exists to catch: a correct derivative passes at
// round-off, and each kind of planted error (one Jacobian entry, the VJP) is reported in its
// own field at about its relative size.
#include <cmath>
#include <limits>

#include <catch2/catch.hpp>

#include "sbptt/core/finite_difference.hpp"
#include "sbptt/sim/linear.hpp"

using namespace sbptt;

namespace {

using Linear = LinearSystem<double, 3, 1>;

Linear linear_system() {
  Linear::StateJacobian a;
  a << 0.9, 0.2, 0.0, -0.1, 1.1, 0.3, 0.0, 0.4, 0.8;
  Linear::ControlJacobian b;
  b << 0.5, 2.0, -1.0;
  return Linear(a, b);
}

/// The linear system with one planted error in A, B or the VJP.
struct PlantedError : Linear {
  enum class Where { Nowhere, StateJacobian, ControlJacobian, Vjp, ControlVjp } where;
  double size;
  PlantedError(Where w, double s) : Linear(linear_system()), where(w), size(s) {}
  void jacobians(const State& x, const Control& u, StateJacobian& a, ControlJacobian& b) const {
    Linear::jacobians(x, u, a, b);
    if (where == Where::StateJacobian) a(1, 0) += size;
    if (where == Where::ControlJacobian) b(2, 0) += size;
  }
  void vjp(const State& x, const Control& u, const State& lambda, State* lambda_x,
           Control* lambda_u) const {
    Linear::vjp(x, u, lambda, lambda_x, lambda_u);
    if (where == Where::Vjp && lambda_x) (*lambda_x)(0) += size * lambda(1);
    if (where == Where::ControlVjp && lambda_u) (*lambda_u)(0) += size * lambda(2);  // B(2, 0)
  }
};

}  // namespace

TEST_CASE("check_jacobians points at the entry of its worst error, with both values",
          "[core][finite_difference]") {
  // The three numbers said which product was wrong, not where: a user with a 12 × 12 A had to
  // difference it again to find the entry.
  using Where = PlantedError::Where;
  const Linear::State x(0.3, -0.7, 0.1);
  const Linear::Control u = Linear::Control::Constant(0.4);
  struct Case {
    Where where;
    char matrix;
    bool from_vjp;
    Index row, col;
    double value;  // the correct one
    const char* words;
  };
  for (const Case& c :
       {Case{Where::StateJacobian, 'A', false, 1, 0, -0.1,
             "at A(1, 0): -0.099 by jacobians, -0.1 by finite differences"},
        Case{Where::ControlJacobian, 'B', false, 2, 0, -1.0,
             "at B(2, 0): -0.999 by jacobians, -1 by finite differences"},
        Case{Where::Vjp, 'A', true, 1, 0, -0.1,
             "at A(1, 0): -0.099 by the vjp, -0.1 by finite differences"},
        Case{Where::ControlVjp, 'B', true, 2, 0, -1.0,
             "at B(2, 0): -0.999 by the vjp, -1 by finite differences"}}) {
    const auto check = check_jacobians(PlantedError(c.where, 1e-3), x, u);
    const WorstEntry<double>& w = check.worst_entry;
    INFO(describe(check));
    CHECK(w.matrix == c.matrix);
    CHECK(w.from_vjp == c.from_vjp);
    CHECK(w.row == c.row);
    CHECK(w.col == c.col);
    CHECK(w.analytic == Approx(c.value + 1e-3).epsilon(1e-12));
    CHECK(w.finite_difference == Approx(c.value).epsilon(1e-8));
    CHECK(w.error == check.worst());
    CHECK_THAT(describe(check), Catch::Contains(c.words));
  }
  const auto clean = check_jacobians(PlantedError(Where::Nowhere, 0), x, u);
  CHECK(clean.worst_entry.error == clean.worst());
  CHECK(clean.worst() < 1e-9);
}

TEST_CASE("check_jacobians passes a correct simulator and names each planted error",
          "[core][finite_difference]") {
  using Where = PlantedError::Where;
  const Linear::State x(0.3, -0.7, 0.1);
  const Linear::Control u = Linear::Control::Constant(0.4);
  const auto clean = check_jacobians(PlantedError(Where::Nowhere, 0), x, u);
  CHECK(clean.worst() < 1e-9);
  for (double size : {1e-3, 1e-5}) {
    INFO("planted error " << size);
    const auto a = check_jacobians(PlantedError(Where::StateJacobian, size), x, u);
    CHECK(a.state_jacobian_error == Approx(size / 1.1).epsilon(1e-3));  // / max |A| = 1.1
    CHECK(a.control_jacobian_error < 1e-9);
    CHECK(a.vjp_error < 1e-9);  // the VJP is measured against the step, not against A
    const auto b = check_jacobians(PlantedError(Where::ControlJacobian, size), x, u);
    CHECK(b.control_jacobian_error == Approx(size / 2.0).epsilon(1e-3));  // / max |B| = 2
    CHECK(b.state_jacobian_error < 1e-9);
    CHECK(b.vjp_error < 1e-9);  // a wrong B flags B alone
    const auto v = check_jacobians(PlantedError(Where::Vjp, size), x, u);
    CHECK(v.vjp_error == Approx(size / 1.1).epsilon(1e-3));  // Aᵀ(0, 1) = A(1, 0)
    CHECK(std::max(v.state_jacobian_error, v.control_jacobian_error) < 1e-9);
  }
}

TEST_CASE("check_jacobians checks the VJP of a simulator that forms no Jacobians",
          "[core][finite_difference]") {
  /// x' = (sin x₀ + u₀, x₀ x₁ − u₁): step and VJP only, the VJP's ∂x₁'/∂x₀ planted wrong by
  /// `size`.
  struct VjpOnly {
    using Scalar = double;
    using State = Eigen::Vector2d;
    using Control = Eigen::Vector2d;
    double size = 0;
    Index state_dim() const { return 2; }
    Index control_dim() const { return 2; }
    void step(const State& x, const Control& u, State& next) const {
      next << std::sin(x(0)) + u(0), x(0) * x(1) - u(1);
    }
    void vjp(const State& x, const Control&, const State& l, State* lx, Control* lu) const {
      if (lx) *lx << std::cos(x(0)) * l(0) + (x(1) + size) * l(1), x(0) * l(1);
      if (lu) *lu << l(0), -l(1);
    }
  };
  static_assert(Simulator<VjpOnly> && !SimulatorWithJacobians<VjpOnly>);
  const Eigen::Vector2d x(0.4, -1.3);
  const Eigen::Vector2d u(0.2, -0.7);
  const auto clean = check_jacobians(VjpOnly{}, x, u);
  CHECK_FALSE(clean.has_jacobians);
  CHECK(clean.worst() < 1e-9);
  const auto wrong = check_jacobians(VjpOnly{.size = 1e-4}, x, u);
  CHECK(wrong.vjp_error == Approx(1e-4 / 1.3).epsilon(1e-3));  // / max |A| = |x₁|
}

TEST_CASE("check_jacobians' worst() is NaN when any derivative is NaN", "[core][finite_difference]") {
  const Linear::State x(0.3, -0.7, 0.1);
  const Linear::Control u = Linear::Control::Constant(0.4);
  const auto check = check_jacobians(
      PlantedError(PlantedError::Where::Vjp, std::numeric_limits<double>::quiet_NaN()), x, u);
  CHECK(check.state_jacobian_error < 1e-9);
  CHECK(std::isnan(check.vjp_error));
  CHECK(std::isnan(check.worst()));
  CHECK(check.worst_entry.matrix == 'A');  // the first NaN, λ = e_0's λ_x(0)
  CHECK(check.worst_entry.from_vjp);
  CHECK(check.worst_entry.row == 0);
  CHECK(check.worst_entry.col == 0);
  CHECK(std::isnan(check.worst_entry.analytic));
  // NaN in the VJP's control product only: the second of the two errors vjp_error joins.
  const PlantedError control(PlantedError::Where::ControlVjp,
                             std::numeric_limits<double>::quiet_NaN());
  CHECK(std::isnan(check_jacobians(control, x, u).vjp_error));
  CHECK(std::isnan(vjp_jacobian_mismatch(control, x, u)));
}

TEST_CASE("relative_error is NaN when either side holds a NaN anywhere", "[core][finite_difference]") {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  Matrix<double> reference(1, 20), analytic(1, 20);
  reference.setConstant(1.0);
  analytic.setConstant(1.0);
  for (const Index at : {Index{0}, Index{7}, Index{19}}) {
    INFO("NaN at " << at);
    Matrix<double> bad = analytic;
    bad(at) = nan;
    CHECK(std::isnan(relative_error<double>(bad, reference)));
    CHECK(std::isnan(relative_error<double>(analytic, bad)));
  }
  CHECK(relative_error<double>(analytic, reference) == 0);
  // A product never written (empty) or of another shape is infinitely wrong, not right.
  CHECK(std::isinf(relative_error<double>(Matrix<double>(), reference)));
  CHECK(std::isinf(relative_error<double>(analytic.transpose(), reference)));
}
