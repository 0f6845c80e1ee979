// Must NOT compile: a simulator without vjp. The test checks the compiler's message names the
// missing member in plain words.
#include <sbptt/sbptt.hpp>

struct NoVjp {
  using Scalar = double;
  using State = Eigen::Vector2d;
  using Control = Eigen::Matrix<double, 1, 1>;
  using StateJacobian = Eigen::Matrix2d;
  using ControlJacobian = Eigen::Vector2d;
  sbptt::Index state_dim() const { return 2; }
  sbptt::Index control_dim() const { return 1; }
  double dt() const { return 0.1; }
  void step(const State& x, const Control&, State& next) const { next = x; }
  void jacobians(const State&, const Control&, StateJacobian& a, ControlJacobian& b) const {
    a.setIdentity();
    b.setZero();
  }
};

int main() {
  const NoVjp sim;
  auto network = sbptt::Network<double>::mlp(2, {4}, 1);
  using Loss = sbptt::SquaredDistanceLoss<NoVjp::State>;
  sbptt::Engine engine(sim, network, sbptt::Objective<Loss>{}, 3);
  return 0;
}
