// Must NOT compile: AutoDiffSimulator calls the model's step with automatic-differentiation
// numbers, so a step written for double only cannot give the Jacobians.
#include <sbptt/sbptt.hpp>

struct DoubleOnly {
  static constexpr int kStateSize = 2, kControlSize = 1;
  void step(const sbptt::ColumnOf<double, 2>& x, const sbptt::ColumnOf<double, 1>& u,
            sbptt::ColumnOf<double, 2>& next) const {
    next(1) = x(1) + 0.1 * u(0);
    next(0) = x(0) + 0.1 * next(1);
  }
};

int main() {
  const sbptt::AutoDiffSimulator<DoubleOnly> sim;
  Eigen::Matrix2d a;
  Eigen::Vector2d b;
  sim.jacobians(Eigen::Vector2d(1.0, 2.0), Eigen::Matrix<double, 1, 1>(0.5), a, b);
  return 0;
}
