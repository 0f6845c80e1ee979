// Must NOT compile: a second-order model (it has `acceleration`) whose hand-written Jacobians
// are named derivative_jacobians; Integrated would never call them.
#include <sbptt/sbptt.hpp>

struct Spring {
  static constexpr int kStateSize = 2, kControlSize = 1;
  template <class T>
  void acceleration(const sbptt::ColumnOf<T, 2>& x, const sbptt::ColumnOf<T, 1>& u,
                    sbptt::ColumnOf<T, 1>& a) const {
    a(0) = -x(0) + u(0);
  }
  void derivative_jacobians(const sbptt::ColumnOf<double, 2>&, const sbptt::ColumnOf<double, 1>&,
                            Eigen::Matrix<double, 2, 2>& fx, Eigen::Matrix<double, 2, 1>& fu) const {
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
