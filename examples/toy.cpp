// The paper's Fig. 1 toy problem (docs/paper.md §3.1): x' = x + c with c = θ1 x² + θ2 x, from
// x_0 = −0.3 to the target 2 in 4 steps, L = ½ (x_4 − 2)². Parameters start at 0 unless
// --init-params gives them (two lines: θ1, θ2).
//   toy --init-params theta.txt --dump-gradients g.csv
#include "polynomial_policy.hpp"
#include "task_program.hpp"

using namespace sbptt;
using sbptt::examples::Task;
using sbptt::examples::TaskOptions;

template <class Scalar>
int run(const TaskOptions& o) {
  using Sim = LinearSystem<Scalar, 1, 1>;
  using Loss = SquaredDistanceLoss<typename Sim::State>;
  const Sim sim = Sim::scalar(Scalar(1), Scalar(1));
  testing::PolynomialPolicy<Scalar> policy({2, 1});
  typename Sim::State target;
  target(0) = Scalar(2);
  const Matrix<Scalar> starts = Matrix<Scalar>::Constant(1, o.samples, Scalar(-0.3));
  return examples::train(o, sim, policy, Objective<Loss>{Loss{target}}, o.time.steps,
                         examples::DataSplit<Scalar>{starts, starts});
}

int main(int argc, char** argv) {
  return examples::task_main(Task::Toy, argc, argv,
                             []<class Scalar>(const TaskOptions& o) { return run<Scalar>(o); });
}
