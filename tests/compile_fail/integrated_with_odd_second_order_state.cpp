// Must NOT compile: a second-order model's state is (q, v), two halves of one size, so a fixed
// kStateSize of 3 cannot be one (its acceleration into ColumnOf<T, 3/2 = 1> looks well-formed).
// Before the static check this compiled and threw only when the simulator was constructed.
#include <sbptt/sbptt.hpp>

struct OddPendulum {
  static constexpr int kStateSize = 3, kControlSize = 1;
  template <class T>
  void acceleration(const sbptt::ColumnOf<T, 3>& x, const sbptt::ColumnOf<T, 1>& u,
                    sbptt::ColumnOf<T, 1>& a) const {
    a(0) = -x(0) + u(0);
  }
};

int main() {
  const sbptt::Integrated<OddPendulum, sbptt::Heun> sim(OddPendulum{}, 0.1);
  Eigen::Vector3d next;
  sim.step(Eigen::Vector3d(1.0, 2.0, 3.0), Eigen::Matrix<double, 1, 1>(0.5), next);
  return 0;
}
