// Must NOT compile: a second-order model (it has `acceleration`) whose hand-written Jacobians
// are named derivative_jacobians; Integrated would never call them.
#include "spring.hpp"

struct Spring : SpringAcceleration {
  void derivative_jacobians(const Eigen::Vector2d&, const Eigen::Matrix<double, 1, 1>&,
                            Eigen::Matrix2d& fx, Eigen::Vector2d& fu) const {
    fx << 0, 1, -1, 0;
    fu << 0, 1;
  }
};

int main() {
  const sbptt::Integrated<Spring, sbptt::Heun> sim(Spring{}, 0.1);
  Eigen::Vector2d next;
  sim.step(Eigen::Vector2d(1.0, 2.0), Eigen::Matrix<double, 1, 1>(0.5), next);
  return 0;
}
