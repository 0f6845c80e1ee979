// Must NOT compile: a derivative written for double only, with no hand-written Jacobians, is
// called with automatic-differentiation numbers; the message says it must be a template.
#include <sbptt/sbptt.hpp>

struct Decay {
  static constexpr int kStateSize = 1, kControlSize = 1;
  void derivative(const sbptt::ColumnOf<double, 1>& x, const sbptt::ColumnOf<double, 1>& u,
                  sbptt::ColumnOf<double, 1>& xdot) const {
    xdot(0) = -x(0) + u(0);
  }
};

int main() {
  const sbptt::Integrated<Decay, sbptt::Heun> sim(Decay{}, 0.1);
  Eigen::Matrix<double, 1, 1> next;
  sim.step(Eigen::Matrix<double, 1, 1>(1.0), Eigen::Matrix<double, 1, 1>(0.5), next);
  return 0;
}
