// Smallest downstream program: the paper's toy problem through the installed headers.
// Exits non-zero unless the engine reproduces g_R at θ = (0, 0) from docs/paper.md §3.1.
#include <cmath>
#include <cstdio>

#include <sbptt/sbptt.hpp>

int main() {
  using Sim = sbptt::LinearSystem<double, 1, 1>;
  using Loss = sbptt::SquaredDistanceLoss<Sim::State>;
  const Sim toy = Sim::scalar(1.0, 1.0);  // x' = x + c
  auto policy = sbptt::Network<double>::mlp(1, {4}, 1);
  policy.params().setZero();  // c ≡ 0, so g_R is the table's first row for the output bias
  Sim::State target;
  target << 2.0;
  sbptt::Engine engine(toy, policy, sbptt::Objective<Loss>{Loss{target}}, 4);
  const auto result = engine.regular_and_modified(sbptt::Matrix<double>::Constant(1, 1, -0.3));
  // With c ≡ 0, x_4 = -0.3 and ∂L/∂bias = (x_4 − 2) · 4 = −9.2.
  const double bias_gradient = result.regular(result.regular.size() - 1);
  std::printf("%s code: loss = %.6f, dL/d(output bias) = %.6f (expected -9.2)\n",
              sbptt::instruction_set(), result.loss, bias_gradient);
  return std::abs(bias_gradient + 9.2) < 1e-12 ? 0 : 1;
}
