// The paper's multi-pole cart-pole swing-up (docs/paper.md §5): one force swings 1–4 poles up within
// T = 1 s. MLP 2×100 tanh with a zeroed last kernel, final-state loss 1 − mean cos θ_i.
//   cartpole --poles 4 --method C --clip norm --epochs 50 --csv out.csv
//   cartpole --poles 4 --physical       poles coupled through the cart (CartPoleModel::Physical)
//   cartpole --poles 3 --model chain    1–3 links hinged end to end (CartChain, sim/cart_chain.hpp)
#include "task_program.hpp"

using namespace sbptt;
using sbptt::examples::Task;
using sbptt::examples::TaskOptions;

template <class Scalar, int Poles>
int run(const TaskOptions& o) {
  CartPoleOptions options;
  options.horizon = o.time.horizon();
  options.steps = o.time.steps;
  if (o.physical) options.model = CartPoleModel::Physical;
  const CartPole<Scalar, Poles> sim(options);
  Rng data_rng(o.seed);
  auto network = Network<Scalar>::mlp(sim.state_dim(), {100, 100}, 1);
  Rng init_rng(o.seed + 1);
  glorot_uniform(network, init_rng, {.zero_last_kernel = true});
  auto data = examples::generated_sets<Scalar>(o, sim.state_dim(), network, [&](Index count) {
    return cartpole_initial_states(sim, data_rng, count);
  });
  return examples::train(o, sim, network, cartpole_objective<Scalar, Poles>(), o.time.steps,
                         std::move(data));
}

/// The serial chain of `Links` links: the same data, network and loss as the cart pole with
/// as many poles (the state layouts agree), semi-implicit Euler at the cart pole's dt.
template <class Scalar, int Links>
int run_chain(const TaskOptions& o) {
  const CartChain<Scalar, Links> sim(CartChainModel<Links>{}, static_cast<Scalar>(o.time.dt));
  Rng data_rng(o.seed);
  auto network = Network<Scalar>::mlp(sim.state_dim(), {100, 100}, 1);
  Rng init_rng(o.seed + 1);
  glorot_uniform(network, init_rng, {.zero_last_kernel = true});
  auto data = examples::generated_sets<Scalar>(o, sim.state_dim(), network, [&](Index count) {
    return cartpole_initial_states<Scalar>(Links, data_rng, count);
  });
  return examples::train(o, sim, network, cartpole_objective<Scalar, Links>(), o.time.steps,
                         std::move(data));
}

int main(int argc, char** argv) {
  return examples::task_main(Task::CartPole, argc, argv, []<class Scalar>(const TaskOptions& o) {
    if (o.chain) {
      switch (o.poles) {
        case 1: return run_chain<Scalar, 1>(o);
        case 2: return run_chain<Scalar, 2>(o);
        default: return run_chain<Scalar, 3>(o);
      }
    }
    switch (o.poles) {
      case 1: return run<Scalar, 1>(o);
      case 2: return run<Scalar, 2>(o);
      case 3: return run<Scalar, 3>(o);
      default: return run<Scalar, 4>(o);
    }
  });
}
