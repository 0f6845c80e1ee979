// A simulator of the user's whose step, VJP or Jacobians (or, for a batch simulator, whose
// step_batch or vjp_batch) write another size than its state_dim() or control_dim() is refused
// with InvalidArgument, naming the product, the size it had and the size expected: by the
// engine's forward pass, its sweeps and its evaluation, and by check_jacobians. Before, a step
// of 3 entries for 2 trained with the third dropped, and a λ_x of 1 entry for 2 was read past
// its end (AddressSanitizer: heap-buffer-overflow in detail::vjp_columns), both with no error
// in a Release build.
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

Matrix<double> oscillator_a() {
  Matrix<double> a(2, 2);
  a << 1.0, 0.1, -0.1, 0.98;
  return a;
}

Matrix<double> oscillator_b() {
  Matrix<double> b(2, 1);
  b << 0.005, 0.1;
  return b;
}

Base oscillator() { return Base(oscillator_a(), oscillator_b()); }

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

TEST_CASE("check_jacobians refuses a simulator's step, VJP or Jacobians of the wrong size",
          "[bptt][engine]") {
  const Vector<double> x = Vector<double>::Constant(2, 0.3);
  const Vector<double> u = Vector<double>::Constant(1, -0.5);
  for (const Case& c : cases) {
    INFO(c.message);
    const WrongSize sim(c.product, c.size);
    CHECK_THROWS_WITH(check_jacobians(sim, x, u), Catch::Contains(c.message));
  }
  // A of 3 × 2: compared as it was, it gave an error of infinity and named nothing.
  struct WrongJacobians : Base {
    WrongJacobians() : Base(oscillator()) {}
    void jacobians(const State& x, const Control& u, StateJacobian& a, ControlJacobian& b) const {
      Base::jacobians(x, u, a, b);
      a = StateJacobian::Ones(3, 2);
    }
  };
  const WrongJacobians wrong;
  const char* message = "the simulator's jacobians wrote A of 3 × 2; expected state_dim() × "
                        "state_dim() = 2 × 2";
  CHECK_THROWS_WITH(check_jacobians(wrong, x, u), Catch::Contains(message));
  CHECK_THROWS_WITH(vjp_jacobian_mismatch(wrong, x, u), Catch::Contains(message));
}

namespace {

/// The oscillator as a `BatchSimulator` whose step_batch writes a row too many, or whose
/// vjp_batch writes Bᵀλ with a column too few.
struct WrongBatch : Base {
  bool wrong_step;
  Matrix<double> a = oscillator_a(), b = oscillator_b();
  explicit WrongBatch(bool step) : Base(oscillator()), wrong_step(step) {}
  void step_batch(const Matrix<double>& x, const Matrix<double>& u, Matrix<double>& x_next) const {
    x_next = a * x + b * u;
    if (wrong_step) x_next = Matrix<double>::Ones(x.rows() + 1, x.cols());
  }
  void vjp_batch(const Matrix<double>& x, const Matrix<double>& u, const Matrix<double>& lambda,
                 Matrix<double>* lambda_x, Matrix<double>* lambda_u) const {
    if (lambda_x != nullptr) *lambda_x = a.transpose() * lambda;
    if (lambda_u != nullptr) *lambda_u = b.transpose() * lambda;
    if (!wrong_step && lambda_u != nullptr)
      *lambda_u = Matrix<double>::Ones(u.rows(), x.cols() - 1);
  }
};

}  // namespace

TEST_CASE("The engine refuses a batch simulator's products of the wrong shape, one sweep or two",
          "[bptt][engine]") {
  static_assert(BatchSimulator<WrongBatch>);
  using Loss = SquaredDistanceLoss<Vector<double>>;
  const Objective<Loss> objective{Loss{Vector<double>::Zero(2)}};
  const Matrix<double> x0 = Matrix<double>::Constant(2, 4, 0.25);
  auto network = Network<double>::mlp(2, {8}, 1);
  Rng rng(3);
  glorot_uniform(network, rng);
  const WrongBatch wrong_step(true), wrong_vjp(false);
  Engine<WrongBatch, Network<double>, Loss> stepping(wrong_step, network, objective, 6);
  CHECK_THROWS_WITH(stepping.forward(x0),
                    Catch::Contains("the simulator's step_batch wrote x_next of 3 × 4; expected "
                                    "state_dim() × B = 2 × 4"));
  Engine<WrongBatch, Network<double>, Loss> sweeping(wrong_vjp, network, objective, 6);
  Vector<double> gradient;
  (void)sweeping.forward(x0);
  CHECK_THROWS_WITH(sweeping.reverse(FlowMode::Full, gradient),
                    Catch::Contains("the simulator's vjp_batch wrote lambda_u (Bᵀλ) of 1 × 3; "
                                    "expected control_dim() × columns = 1 × 4"));
  // The combined update's two sweeps share one call of 2B columns.
  CHECK_THROWS_WITH(sweeping.regular_and_modified(x0),
                    Catch::Contains("the simulator's vjp_batch wrote lambda_u (Bᵀλ) of 1 × 7; "
                                    "expected control_dim() × columns = 1 × 8"));
}
