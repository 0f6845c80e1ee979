// Must NOT compile: an acceleration written into a vector of the state's size (2) instead of
// half of it (1) is neither a first- nor a second-order model; the message says what each needs.
#include <sbptt/sbptt.hpp>

struct Spring {
  static constexpr int kStateSize = 2, kControlSize = 1;
  template <class T>
  void acceleration(const sbptt::ColumnOf<T, 2>& x, const sbptt::ColumnOf<T, 1>& u,
                    sbptt::ColumnOf<T, 2>& a) const {
    a(0) = x(1);
    a(1) = -x(0) + u(0);
  }
};

int main() {
  const sbptt::Integrated<Spring, sbptt::Heun> sim(Spring{}, 0.1);
  Eigen::Vector2d next;
  sim.step(Eigen::Vector2d(1.0, 2.0), Eigen::Matrix<double, 1, 1>(0.5), next);
  return 0;
}
