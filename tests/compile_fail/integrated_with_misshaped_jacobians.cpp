// Must NOT compile: hand-written a-Jacobians of a 2-state model with a_x declared 1 × 3 (it is
// 1 × 2) could not be called, and were silently replaced by automatic ones; the message gives
// the signature they need.
#include "spring.hpp"

struct Spring : SpringAcceleration {
  void acceleration_jacobians(const Eigen::Vector2d&, const Eigen::Matrix<double, 1, 1>&,
                              Eigen::Matrix<double, 1, 3>& ax,  // 1 × 2 for two states
                              Eigen::Matrix<double, 1, 1>& au) const {
    ax << -1.0, 0.0, 0.0;
    au << 1.0;
  }
};

int main() {
  const sbptt::Integrated<Spring, sbptt::SemiImplicitEuler> sim(Spring{}, 0.1);
  Eigen::Matrix2d a;
  Eigen::Vector2d b;
  sim.jacobians(Eigen::Vector2d(1.0, 2.0), Eigen::Matrix<double, 1, 1>(0.5), a, b);
  return 0;
}
