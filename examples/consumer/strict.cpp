// The headers under a user's strict warnings (-Wall -Wextra -Werror, portable code), with a
// fixed-size state of 4: the engine's per-thread scratch once copied vectors it had only
// sized, and GCC 12 warned (-Wmaybe-uninitialized) 25 times in this program. Exits non-zero
// unless the engine reproduces the closed form of x_4 for x' = x + (1, 1, 1, 1) c with c ≡ 0.
#include <cmath>
#include <cstdio>

#include <sbptt/sbptt.hpp>

int main() {
  using Sim = sbptt::LinearSystem<double, 4, 1>;
  using Loss = sbptt::SquaredDistanceLoss<Sim::State>;
  const Sim drift(Eigen::Matrix4d::Identity(), Eigen::Vector4d::Ones());
  auto policy = sbptt::Network<double>::mlp(4, {8}, 1);
  policy.params().setZero();  // c ≡ 0: the state stays where it starts
  sbptt::Engine engine(drift, policy, sbptt::Objective<Loss>{Loss{Sim::State::Zero()}}, 4);
  const auto result = engine.regular_and_modified(sbptt::Matrix<double>::Constant(4, 2, 0.3));
  // Each sample ends at (0.3, 0.3, 0.3, 0.3): ½ |x|² = 0.18, the mean of two equal samples.
  std::printf("loss = %.6f (expected 0.18)\n", result.loss);
  return std::abs(result.loss - 0.18) < 1e-12 ? 0 : 1;
}
