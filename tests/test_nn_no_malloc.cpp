// After a warm-up call, forward and backward at an unchanged batch size allocate nothing
// (Eigen's runtime malloc check, turned into an exception so that Release builds see it).
#include <stdexcept>

#define EIGEN_RUNTIME_NO_MALLOC
#define eigen_assert(x) \
  do {                  \
    if (!(x)) throw std::runtime_error("Eigen assertion failed: " #x); \
  } while (false)

#include <catch2/catch.hpp>

#include "sbptt/nn/init.hpp"
#include "sbptt/nn/network.hpp"

using sbptt::Activation;
using sbptt::Conv1d;
using sbptt::Dense;
using sbptt::Index;
using sbptt::Network;

namespace {

struct MallocGuard {
  MallocGuard() { Eigen::internal::set_is_malloc_allowed(false); }
  ~MallocGuard() { Eigen::internal::set_is_malloc_allowed(true); }
};

template <class Scalar>
void check_no_allocation(Network<Scalar>& net, Index batch) {
  sbptt::Rng rng(5);
  sbptt::glorot_uniform(net, rng);
  sbptt::Matrix<Scalar> x = sbptt::Matrix<Scalar>::Random(net.input_dim(), batch);
  sbptt::Matrix<Scalar> dy = sbptt::Matrix<Scalar>::Random(net.output_dim(), batch);
  sbptt::Matrix<Scalar> y, dx;
  sbptt::Vector<Scalar> grad = sbptt::Vector<Scalar>::Zero(net.num_params());
  typename Network<Scalar>::Workspace ws;
  net.forward(x, y, ws);
  net.backward(ws, dy, grad, &dx);
  const sbptt::Vector<Scalar> first = grad;

  {
    MallocGuard guard;
    for (int repeat = 0; repeat < 3; ++repeat) {
      net.forward(x, y, ws);
      net.backward(ws, dy, grad, &dx);
      net.backward(ws, dy, grad, nullptr);
    }
  }
  CHECK(grad.isApprox(7 * first));
}

}  // namespace

TEMPLATE_TEST_CASE("the MLP does not allocate after warm-up", "[nn][malloc]", float, double) {
  auto net = Network<TestType>::mlp(24, {100, 100}, 4);
  REQUIRE_NOTHROW(check_no_allocation(net, 8));
  REQUIRE_NOTHROW(check_no_allocation(net, 1));
}

TEMPLATE_TEST_CASE("the quantum CNN does not allocate after warm-up", "[nn][malloc]", float,
                   double) {
  Network<TestType> net({Conv1d{32, 2, 60, 3, 2, Activation::Tanh},
                         Conv1d{15, 60, 60, 3, 2, Activation::Tanh},
                         Dense{420, 1, Activation::Identity}});
  REQUIRE_NOTHROW(check_no_allocation(net, 8));
}

TEST_CASE("two networks of different shapes in turn on one thread do not allocate",
          "[nn][malloc]") {
  // The calls without packed weights pack into one per-thread scratch; it must keep the
  // largest shape it has seen instead of being resized to each network in turn.
  auto large = Network<float>::mlp(24, {100, 100}, 4);
  auto small = Network<float>::mlp(24, {64}, 4);
  const sbptt::Matrix<float> x = sbptt::Matrix<float>::Random(24, 8);
  const sbptt::Matrix<float> dy = sbptt::Matrix<float>::Random(4, 8);
  sbptt::Matrix<float> y, dx;
  sbptt::Vector<float> large_grad = sbptt::Vector<float>::Zero(large.num_params());
  sbptt::Vector<float> small_grad = sbptt::Vector<float>::Zero(small.num_params());
  Network<float>::Workspace large_ws, small_ws;
  const auto both = [&] {
    large.forward(x, y, large_ws);
    large.backward(large_ws, dy, large_grad, &dx);
    small.forward(x, y, small_ws);
    small.backward(small_ws, dy, small_grad, &dx);
  };
  both();  // warm-up: every buffer sized for both
  MallocGuard guard;
  REQUIRE_NOTHROW(both());
  REQUIRE_NOTHROW(both());
}

TEST_CASE("the malloc check itself fires", "[nn][malloc]") {
  MallocGuard guard;
  REQUIRE_THROWS(sbptt::Matrix<double>(10, 10));
}
