// Must NOT compile: the engine keeps a reference to its controller; a temporary network would
// be destroyed at the end of the statement.
#include <sbptt/sbptt.hpp>

int main() {
  const sbptt::CartPole<double, 1> sim;
  sbptt::Engine engine(sim, sbptt::Network<double>::mlp(4, {8}, 1),
                       sbptt::cartpole_objective<double, 1>(), 10);
  return 0;
}
