// A user-defined simulator trained with the combined update: a point mass on a line with
// friction, pushed by a force u, must stop at the origin (final-state loss).
//   p' = p + dt·v',  v' = v + dt·(u − γ v)        State (p, v), Control (u)
#include <cstdio>

#include <sbptt/sbptt.hpp>

struct PointMass {
  using Scalar = double;
  using State = Eigen::Vector2d;
  using Control = Eigen::Matrix<double, 1, 1>;
  using StateJacobian = Eigen::Matrix2d;
  using ControlJacobian = Eigen::Vector2d;
  double dt_ = 0.1, friction = 0.5;

  sbptt::Index state_dim() const { return 2; }
  sbptt::Index control_dim() const { return 1; }
  double dt() const { return dt_; }
  void jacobians(const State&, const Control&, StateJacobian& a, ControlJacobian& b) const {
    const double damp = 1 - dt_ * friction;
    a << 1, dt_ * damp, 0, damp;
    b << dt_ * dt_, dt_;
  }
  void step(const State& x, const Control& u, State& next) const {
    StateJacobian a;
    ControlJacobian b;
    jacobians(x, u, a, b);
    next = a * x + b * u;
  }
  void vjp(const State& x, const Control& u, const State& l, State* lx, Control* lu) const {
    StateJacobian a;
    ControlJacobian b;
    jacobians(x, u, a, b);
    if (lx) *lx = a.transpose() * l;
    if (lu) *lu = b.transpose() * l;
  }
};

int main() {
  using Loss = sbptt::SquaredDistanceLoss<PointMass::State>;
  const PointMass sim;
  auto network = sbptt::Network<double>::mlp(2, {32, 32}, 1);
  sbptt::Rng rng(1);
  sbptt::glorot_uniform(network, rng, {.zero_last_kernel = true});
  sbptt::Matrix<double> starts(2, 64);
  for (sbptt::Index i = 0; i < starts.size(); ++i) starts(i) = rng.uniform(-1, 1);

  sbptt::Engine engine(sim, network, sbptt::Objective<Loss>{Loss{PointMass::State::Zero()}}, 30);
  sbptt::CombinedUpdate<sbptt::Adam<double>> update(sbptt::Adam<double>({.learning_rate = 3e-3}));
  for (int iteration = 0; iteration <= 1000; ++iteration) {
    const auto pair = engine.regular_and_modified(starts);  // one forward pass, two sweeps
    if (iteration % 200 == 0)
      std::printf("iteration %4d  loss %.3e  cos(g_M, g_R) %+.3f  signs agree %.2f\n", iteration,
                  pair.loss, pair.comparison.cos_modified_regular, pair.comparison.agree_fraction);
    update.step(network.params(), pair.modified, pair.regular);
  }
  return 0;
}
