// After a warm-up call at a batch shape, the engine's forward pass, its reverse sweeps and the
// combined pair allocate nothing: Eigen's runtime malloc check, with every failed Eigen
// assertion counted so that Release builds see it. (Counted, not thrown as in
// test_nn_no_malloc.cpp: an exception in the middle of an Eigen resize would leave the matrix
// half-built, and the engine's buffers must stay usable for the check that the guard fires.)
// A replaced global operator new counts every other heap allocation. Covers forward, both
// reverse sweeps, the combined pair and evaluate, for the paper's cart pole (MLP), guidance
// (MLP, 4 controls) and quantum (CNN) settings at batch 8, in float and double, with 1 and 2
// threads.
#include <atomic>
#include <cstdlib>
#include <new>

namespace {
std::atomic<int> eigen_failures{0};
/// Every operator new of the program: containers, strings and task queues that Eigen's check
/// cannot see.
std::atomic<long> heap_allocations{0};
}  // namespace

#include "support/address_sanitizer.hpp"

// Under ASan its own allocator keeps these functions (they would be mixed with ASan's other
// variants, e.g. nothrow new, and freed by the wrong one); Eigen's check still runs there.
#if !SBPTT_TEST_ADDRESS_SANITIZER
// GCC pairs the free() below with the library's operator new, not with this replacement.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
#endif
void* operator new(std::size_t size) {
  heap_allocations.fetch_add(1);
  if (void* p = std::malloc(size == 0 ? 1 : size)) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
#endif

#define EIGEN_RUNTIME_NO_MALLOC
#define eigen_assert(x)               \
  do {                                \
    if (!(x)) eigen_failures.fetch_add(1); \
  } while (false)

#include <catch2/catch.hpp>

#include <array>
#include <limits>

#include "sbptt/objectives/cartpole.hpp"
#include "sbptt/objectives/guidance.hpp"
#include "sbptt/objectives/quantum.hpp"
#include "sbptt/bptt/engine.hpp"
#include "sbptt/core/finite_difference.hpp"
#include "sbptt/nn/init.hpp"
#include "sbptt/nn/network.hpp"
#include "support/networks.hpp"
#include "sbptt/sim/cartpole.hpp"
#include "sbptt/sim/guidance_by_repulsion.hpp"
#include "sbptt/sim/schrodinger.hpp"

using namespace sbptt;

namespace {

struct MallocGuard {
  MallocGuard() { Eigen::internal::set_is_malloc_allowed(false); }
  ~MallocGuard() { Eigen::internal::set_is_malloc_allowed(true); }
  MallocGuard(const MallocGuard&) = delete;
  MallocGuard& operator=(const MallocGuard&) = delete;
};

/// The heap allocations that `work()` makes with Eigen's allocator switched off; Eigen's
/// refusals go to `eigen_failures`, which starts at 0.
template <class Work>
long allocations_during(Work&& work) {
  eigen_failures = 0;
  const MallocGuard guard;
  const long before = heap_allocations;
  work();
  return heap_allocations - before;
}

/// Warm-up, then the same calls again with Eigen's allocator switched off. The results of the
/// guarded calls must equal the warm-up's (the guard changes nothing but the check). Each
/// thread count gets an engine of its own, so that no buffer is sized by another's calls.
template <class Engine, class Scalar>
void check_no_allocation(Engine& engine, const Matrix<Scalar>& x0, Index threads) {
  engine.set_threads(threads);
  Vector<Scalar> g_full, g_physics;
  GradientPair<Scalar> pair;
  const Scalar loss = engine.forward(x0);
  engine.reverse(FlowMode::Full, g_full);
  engine.reverse(FlowMode::PhysicsOnly, g_physics);
  engine.regular_and_modified(x0, pair);
  const Scalar evaluated = engine.evaluate(x0);
  const Vector<Scalar> first_full = g_full, first_regular = pair.regular,
                       first_modified = pair.modified;
  // With one control the pair shares one backward pass and splits its steps between two
  // threads; the split's tasks' adjoints live in its slots, whichever thread fills or adds
  // them, so the pair allocates nothing after its first call, on any number of threads.
  // Guarded five times, so that the sweeping thread too takes its turns (until the second
  // thread starts, and at the end).
  const std::size_t pair_repeats = threads == 1 ? 1 : 5;

  const Matrix<Scalar> narrower = x0.leftCols(x0.cols() - 1);
  std::array<Scalar, 2> losses{}, evaluations{};
  const long allocations = allocations_during([&] {
    for (std::size_t repeat = 0; repeat < 2; ++repeat) {
      losses[repeat] = engine.forward(x0);
      engine.reverse(FlowMode::Full, g_full);
      engine.reverse(FlowMode::PhysicsOnly, g_physics);
      for (std::size_t k = 0; k < pair_repeats; ++k) engine.regular_and_modified(x0, pair);
      evaluations[repeat] = engine.evaluate(x0);
    }
  });
  CHECK(eigen_failures == 0);
  CHECK(allocations == 0);
  // On two threads the timed decision runs a probing's batches on the threads and then alone
  // (SweepThreading): the batches run alone allocate nothing either, the lone sweep's and the
  // pair's.
  const long probing = allocations_during([&] {
    for (int k = 0; k < 2 * detail::SweepThreadingDecision::probes; ++k) {
      engine.forward(x0);
      engine.reverse(FlowMode::Full, g_full);
      engine.regular_and_modified(x0, pair);
    }
  });
  CHECK(eigen_failures == 0);
  CHECK(probing == 0);
  for (std::size_t repeat = 0; repeat < 2; ++repeat) {
    CHECK(losses[repeat] == loss);
    CHECK(evaluations[repeat] == evaluated);
  }
  CHECK(g_full == first_full);
  CHECK(pair.regular == first_regular);
  CHECK(pair.modified == first_modified);
  // One control: the pair shares the network's backward pass, so it equals the lone sweeps to
  // round-off (test_bptt_shared_seed.cpp; quantum in double: 1.1e-13 = 506 ε).
  const Scalar tolerance = 1000 * std::numeric_limits<Scalar>::epsilon();
  CHECK(relative_error<Scalar>(pair.regular, g_full) < tolerance);
  CHECK(relative_error<Scalar>(pair.modified, g_physics) < tolerance);
  // The guard does see the engine: a new batch shape must resize the stored trajectory.
  {
    MallocGuard guard;
    engine.forward(narrower);
  }
  CHECK(eigen_failures > 0);
}

}  // namespace

TEMPLATE_TEST_CASE("engine: cart pole with the paper's MLP allocates nothing after warm-up",
                   "[bptt][malloc]", float, double) {
  using S = TestType;
  const CartPole<S, 4> sim;
  auto net = Network<S>::mlp(sim.state_dim(), {100, 100}, 1);
  Rng rng(3);
  glorot_uniform(net, rng);  // last kernel not zeroed, so that g is non-trivial everywhere
  const Matrix<S> x0 = cartpole_initial_states(sim, rng, 8);
  for (const Index threads : {1, 2}) {
    INFO("threads " << threads);
    Engine engine(sim, net, cartpole_objective<S, 4>(), 100);
    check_no_allocation(engine, x0, threads);
  }
}

// Truncation is not a shape: a pair whose first call was truncated (every other step cut)
// allocates nothing in an untruncated call, on two threads, where some of the cut steps'
// input adjoints belong to the split's tasks.
TEST_CASE("engine: the pair warmed up with truncation allocates nothing without it",
          "[bptt][malloc]") {
  const CartPole<float, 4> sim;
  auto net = Network<float>::mlp(sim.state_dim(), {100, 100}, 1);
  Rng rng(3);
  glorot_uniform(net, rng);
  Engine engine(sim, net, cartpole_objective<float, 4>(), 100);
  const Matrix<float> x0 = cartpole_initial_states(sim, rng, 8);
  engine.set_threads(2);
  GradientPair<float> pair;
  engine.regular_and_modified(x0, pair, 2);
  const long allocations = allocations_during([&] {
    for (int repeat = 0; repeat < 5; ++repeat) engine.regular_and_modified(x0, pair);
  });
  CHECK(eigen_failures == 0);
  CHECK(allocations == 0);
}

TEMPLATE_TEST_CASE("engine: quantum control with the paper's CNN allocates nothing after "
                   "warm-up", "[bptt][malloc]", float, double) {
  using S = TestType;
  const Schrodinger1D<S, 32> sim;
  auto net = testing::quantum_cnn<S>();
  Rng rng(4);
  glorot_uniform(net, rng);
  const Matrix<S> x0 = sim.initial_states(rng, 8);
  for (const Index threads : {1, 2}) {
    INFO("threads " << threads);
    Engine engine(sim, net, quantum_objective(sim, 4), 24);
    check_no_allocation(engine, x0, threads);
  }
}

// Four controls: the pair's sweeps keep a backward pass each, run step by step together on one
// thread (in float with both sweeps' VJPs in one call) and side by side on two.
TEMPLATE_TEST_CASE("engine: guidance with the paper's MLP allocates nothing after warm-up",
                   "[bptt][malloc]", float, double) {
  using S = TestType;
  const GuidanceByRepulsion<S, 2, 4> sim;
  auto net = Network<S>::mlp(sim.state_dim(), {100, 100}, sim.control_dim());
  Rng rng(5);
  glorot_uniform(net, rng);
  const Matrix<S> x0 = guidance_initial_states(sim, rng, 8);
  for (const Index threads : {1, 2}) {
    INFO("threads " << threads);
    Engine engine(sim, net, guidance_objective(sim, 0.1), sim.steps());
    check_no_allocation(engine, x0, threads);
  }
}

TEST_CASE("engine no-malloc check: the guard itself fires", "[bptt][malloc]") {
  eigen_failures = 0;
  {
    MallocGuard guard;
    const Matrix<double> m(10, 10);
    CHECK(m.size() == 100);
  }
  CHECK(eigen_failures == 1);

  if (sbptt::testing::address_sanitizer) return;  // operator new is ASan's, not counted
  // A direct call, which unlike a new-expression may not be elided.
  const long before = heap_allocations;
  void* counted = ::operator new(64);
  CHECK(heap_allocations - before == 1);
  ::operator delete(counted);
}
