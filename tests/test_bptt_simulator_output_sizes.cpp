// A simulator of the user's whose step or VJP writes a vector of another size than its
// state_dim() or control_dim() is refused with InvalidArgument, naming the product, the size
// it had and the size expected: by the engine's forward pass, its sweeps and its evaluation,
// and by check_jacobians. Before, a step of 3 entries for 2 trained with the third dropped,
// and a λ_x of 1 entry for 2 was read past its end (AddressSanitizer: heap-buffer-overflow in
// detail::vjp_columns), both with no error in a Release build.
#include <string>

#include <catch2/catch.hpp>

#include "sbptt/bptt/engine.hpp"
#include "sbptt/bptt/losses.hpp"
#include "sbptt/core/finite_difference.hpp"
#include "sbptt/nn/init.hpp"
#include "sbptt/nn/network.hpp"
#include "sbptt/sim/linear.hpp"

using namespace sbptt;

namespace {

using Base = LinearSystem<double>;  // run-time sizes: nothing stops a wrong size at compile time

Base oscillator() {
  Matrix<double> a(2, 2), b(2, 1);
  a << 1.0, 0.1, -0.1, 0.98;
  b << 0.005, 0.1;
  return Base(a, b);
}

/// The oscillator with one of its products written at `wrong_size`.
struct WrongSize : Base {
  enum class Product { Step, LambdaX, LambdaU };
  Product product;
  Index wrong_size;
  WrongSize(Product which, Index size) : Base(oscillator()), product(which), wrong_size(size) {}

  void step(const State& x, const Control& u, State& x_next) const {
    Base::step(x, u, x_next);
    if (product == Product::Step) x_next = State::Ones(wrong_size);
  }
  void vjp(const State& x, const Control& u, const State& lambda, State* lambda_x,
           Control* lambda_u) const {
    Base::vjp(x, u, lambda, lambda_x, lambda_u);
    if (product == Product::LambdaX && lambda_x != nullptr) *lambda_x = State::Ones(wrong_size);
    if (product == Product::LambdaU && lambda_u != nullptr) *lambda_u = Control::Ones(wrong_size);
  }
};

struct Case {
  WrongSize::Product product;
  Index size;
  const char* message;
};

const Case cases[] = {
    {WrongSize::Product::Step, 3,
     "the simulator's step wrote x_next of size 3; expected state_dim() = 2"},
    {WrongSize::Product::LambdaX, 1,
     "the simulator's vjp wrote lambda_x (Aᵀλ) of size 1; expected state_dim() = 2"},
    {WrongSize::Product::LambdaU, 2,
     "the simulator's vjp wrote lambda_u (Bᵀλ) of size 2; expected control_dim() = 1"},
};

}  // namespace

TEST_CASE("The engine refuses a simulator's step or VJP of the wrong size, on 1 and 2 threads",
          "[bptt][engine]") {
  using Loss = SquaredDistanceLoss<Vector<double>>;
  const Objective<Loss> objective{Loss{Vector<double>::Zero(2)}};
  Matrix<double> x0(2, 4);
  x0 << 0.1, -0.2, 0.3, 0.4, 0.5, 0.6, -0.7, 0.8;
  for (const Case& c : cases) {
    for (const Index threads : {1, 2}) {
      INFO(c.message << ", " << threads << " thread(s)");
      const WrongSize sim(c.product, c.size);
      auto network = Network<double>::mlp(2, {8}, 1);
      Rng rng(3);
      glorot_uniform(network, rng);
      Engine<WrongSize, Network<double>, Loss> engine(sim, network, objective, 6);
      // Split at any cost, so that two threads do take the samples.
      engine.set_threads(threads, 0.0, SweepThreading::Always);
      Vector<double> gradient;
      const auto run = [&] {
        (void)engine.forward(x0);
        (void)engine.reverse(FlowMode::Full, gradient);
      };
      CHECK_THROWS_AS(run(), InvalidArgument);
      CHECK_THROWS_WITH(run(), Catch::Contains(c.message));
      if (c.product == WrongSize::Product::Step) {
        CHECK_THROWS_WITH(engine.evaluate(x0), Catch::Contains(c.message));
      }
    }
  }
}

TEST_CASE("check_jacobians refuses a simulator's step or VJP of the wrong size",
          "[bptt][engine]") {
  const Vector<double> x = Vector<double>::Constant(2, 0.3);
  const Vector<double> u = Vector<double>::Constant(1, -0.5);
  for (const Case& c : cases) {
    INFO(c.message);
    const WrongSize sim(c.product, c.size);
    CHECK_THROWS_WITH(check_jacobians(sim, x, u), Catch::Contains(c.message));
  }
}
