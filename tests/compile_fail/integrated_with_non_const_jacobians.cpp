// Must NOT compile: hand-written f-Jacobians without `const` could not be called, and were
// silently replaced by automatic ones; the message gives the signature they need.
#include <sbptt/sbptt.hpp>

struct Decay {
  static constexpr int kStateSize = 2, kControlSize = 1;
  template <class T>
  void derivative(const sbptt::ColumnOf<T, 2>& x, const sbptt::ColumnOf<T, 1>& u,
                  sbptt::ColumnOf<T, 2>& xdot) const {
    xdot(0) = -x(0) + u(0);
    xdot(1) = -x(1);
  }
  void derivative_jacobians(const Eigen::Vector2d&, const Eigen::Matrix<double, 1, 1>&,
                            Eigen::Matrix2d& fx, Eigen::Vector2d& fu) {  // no const
    fx = -Eigen::Matrix2d::Identity();
    fu << 1.0, 0.0;
  }
};

int main() {
  const sbptt::Integrated<Decay, sbptt::RungeKutta4> sim(Decay{}, 0.1);
  Eigen::Matrix2d a;
  Eigen::Vector2d b;
  sim.jacobians(Eigen::Vector2d(1.0, 2.0), Eigen::Matrix<double, 1, 1>(0.5), a, b);
  return 0;
}
