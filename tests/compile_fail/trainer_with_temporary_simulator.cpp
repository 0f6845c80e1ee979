// Must NOT compile: the trainer keeps a reference to its simulator (through its engine); a
// temporary one would be destroyed at the end of the statement.
#include <sbptt/sbptt.hpp>

int main() {
  auto network = sbptt::Network<double>::mlp(4, {8}, 1);
  sbptt::Trainer trainer(sbptt::CartPole<double, 1>(), network,
                         sbptt::cartpole_objective<double, 1>(), 10,
                         sbptt::Adam<double>(), sbptt::TrainerOptions{});
  return 0;
}
