// Must NOT compile: a controller without backward.
#include <sbptt/sbptt.hpp>

struct NoBackward {
  using Scalar = double;
  struct Workspace {};
  sbptt::Index input_dim() const { return 1; }
  sbptt::Index output_dim() const { return 1; }
  sbptt::Index num_params() const { return 1; }
  const sbptt::Vector<double>& params() const { return theta; }
  sbptt::Vector<double>& params() { return theta; }
  void forward(const sbptt::Matrix<double>& x, sbptt::Matrix<double>& y, Workspace&) const { y = x; }
  sbptt::Vector<double> theta = sbptt::Vector<double>::Zero(1);
};

int main() {
  const auto sim = sbptt::LinearSystem<double>::scalar(1.0, 1.0);
  NoBackward controller;
  using Loss = sbptt::SquaredDistanceLoss<sbptt::LinearSystem<double>::State>;
  sbptt::Engine engine(sim, controller, sbptt::Objective<Loss>{}, 3);
  return 0;
}
