// Must NOT compile: the engine keeps a reference to its simulator, and a temporary one would
// be destroyed at the end of the statement (reading freed stack memory afterwards).
#include <sbptt/sbptt.hpp>

int main() {
  auto network = sbptt::Network<double>::mlp(4, {8}, 1);
  sbptt::Engine engine(sbptt::CartPole<double, 1>(), network,
                       sbptt::cartpole_objective<double, 1>(), 10);
  return 0;
}
