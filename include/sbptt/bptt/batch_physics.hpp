#pragma once
/// \file The simulator's part of one step for a whole batch (columns are samples): a
/// `BatchSimulator` gets one call; any other simulator one call per sample, through the
/// caller's `for_each_sample(body)`, which calls `body(b, scratch)` for every sample b with a
/// thread's `SampleScratch` (serially or over threads, as the caller decides). Implementation
/// details of `sbptt::Engine`; the forward rollout, the evaluation and the reverse sweeps all
/// go through here, so that the two paths are chosen in one place.
#include <algorithm>

#include "sbptt/core/concepts.hpp"
#include "sbptt/core/simulator_output.hpp"
#include "sbptt/core/types.hpp"
#include "sbptt/core/unroll.hpp"

namespace sbptt::detail {

/// Temporaries of the per-sample work of one thread (sized once; never shared by two threads).
template <class State, class Control>
struct SampleScratch {
  State x, x_next, seed, lambda_sample, lambda_x;
  Control u, lambda_u;

  /// Zeroed, not only sized: the engine copies one scratch to every thread, and a copy of
  /// fixed-size vectors never written reads indeterminate values (GCC's -Wmaybe-uninitialized
  /// in a user's build).
  SampleScratch(Index state_dim, Index control_dim) {
    for (State* v : {&x, &x_next, &seed, &lambda_sample, &lambda_x}) v->setZero(state_dim);
    u.setZero(control_dim);
    lambda_u.setZero(control_dim);
  }
};

/// P(t.x, t.u) into t.x_next for one sample, in one machine copy (SBPTT_ONE_COPY) for the
/// forward pass on one thread, the forward pass in parts and the evaluation: compiled into each
/// of their loops, the quantum step on a run-time grid gave other last bits per thread count.
template <class Sim, class Scratch>
SBPTT_ONE_COPY void step_sample(const Sim& sim, Scratch& t) {
  sim.step(t.x, t.u, t.x_next);
  check_step_output(t.x_next, t.x.size());
}

/// x_next = P(x, u) for every column (x_next sized state_dim × B by the caller).
template <class Sim, class Scalar, class ForEachSample>
void step_columns(const Sim& sim, const Matrix<Scalar>& x, const Matrix<Scalar>& u,
                  Matrix<Scalar>& x_next, ForEachSample&& for_each_sample) {
  if constexpr (BatchSimulator<Sim>) {
    sim.step_batch(x, u, x_next);
    check_output_shape("step_batch", "x_next", x_next, "state_dim() × B", x.rows(), x.cols());
  } else {
    for_each_sample([&](Index b, auto& t) {
      t.x = x.col(b);
      t.u = u.col(b);
      step_sample(sim, t);
      x_next.col(b) = t.x_next;
    });
  }
}

/// The two sweeps of a pair side by side for one `vjp_batch` call of a simulator without
/// `vjp_batch_pair` (core/concepts.hpp): [x x], [u u], [λ₁ λ₂] and the results, 2B columns.
/// A `BatchSimulator`'s column does not depend on the others, so the results are the two
/// calls' bit for bit; and where a batch fills less than a block of lanes (the paper's 8
/// samples in 16 float lanes) both sweeps share one block instead of two. Column-major, so
/// each half is one contiguous run of entries and goes in and out by one copy: guidance's five
/// a step took 52–79 ns, Eigen's assignments of column blocks 70–104
/// (docs/benchmark-runs-zen4.md, thirty-fourth run).
template <class Scalar>
struct PairedColumns {
  Matrix<Scalar> x, u, lambda, lambda_x, lambda_u;

  /// [a b] into `into`; a and b have the same shape.
  static void place(const Matrix<Scalar>& a, const Matrix<Scalar>& b, Matrix<Scalar>& into) {
    into.resize(a.rows(), 2 * a.cols());
    const Index half = a.size();
    std::copy_n(a.data(), half, into.data());
    std::copy_n(b.data(), half, into.data() + half);
  }

  /// [a b] = `from` (an even number of columns): a and b get its halves.
  static void split(const Matrix<Scalar>& from, Matrix<Scalar>& a, Matrix<Scalar>& b) {
    const Index cols = from.cols() / 2;
    a.resize(from.rows(), cols);
    b.resize(from.rows(), cols);
    const Index half = a.size();
    std::copy_n(from.data(), half, a.data());
    std::copy_n(from.data() + half, half, b.data());
  }
};

/// For each of `sweeps` (pointers to buffers with `lambda`, `mu`, `propagated`, all with B
/// columns): mu = Bᵀλ per column and, when `physics`, propagated = Aᵀλ, at the step (x, u).
/// `seed(b, t)`, if `seeded`, first adds sample b's loss seed to every sweep's λ. Per sample,
/// the seed and the VJPs of all sweeps share one pass (one fork when the loop is split); a
/// `BatchSimulator` gets one call for two sweeps: `vjp_batch_pair` if it has one, else
/// `vjp_batch` through `paired`.
template <class Sim, class Scalar, class Sweeps, class Seed, class ForEachSample>
void vjp_columns(const Sim& sim, const Matrix<Scalar>& x, const Matrix<Scalar>& u,
                 const Sweeps& sweeps, bool physics, bool seeded, Seed&& seed,
                 ForEachSample&& for_each_sample, PairedColumns<Scalar>& paired) {
  if constexpr (BatchSimulator<Sim>) {
    // B columns per sweep; 2B in the one call that `paired` feeds, checked before its split.
    const auto check_outputs = [&](const char* call, const auto& lambda_u, const auto& lambda_x,
                                   Index cols) {
      check_output_shape(call, "lambda_u (Bᵀλ)", lambda_u, "control_dim() × columns", u.rows(),
                         cols);
      if (physics)
        check_output_shape(call, "lambda_x (Aᵀλ)", lambda_x, "state_dim() × columns", x.rows(),
                           cols);
    };
    if (seeded) for_each_sample(seed);
    if (sweeps.size() == 2) {
      auto* first = *sweeps.begin();
      auto* second = *(sweeps.begin() + 1);
      if constexpr (PairedBatchSimulator<Sim>) {
        sim.vjp_batch_pair(x, u, first->lambda, second->lambda,
                           physics ? &first->propagated : nullptr,
                           physics ? &second->propagated : nullptr, &first->mu, &second->mu);
        for (auto* s : sweeps) check_outputs("vjp_batch_pair", s->mu, s->propagated, x.cols());
      } else {
        PairedColumns<Scalar>::place(x, x, paired.x);
        PairedColumns<Scalar>::place(u, u, paired.u);
        PairedColumns<Scalar>::place(first->lambda, second->lambda, paired.lambda);
        sim.vjp_batch(paired.x, paired.u, paired.lambda, physics ? &paired.lambda_x : nullptr,
                      &paired.lambda_u);
        check_outputs("vjp_batch", paired.lambda_u, paired.lambda_x, 2 * x.cols());
        PairedColumns<Scalar>::split(paired.lambda_u, first->mu, second->mu);
        if (physics)
          PairedColumns<Scalar>::split(paired.lambda_x, first->propagated, second->propagated);
      }
      return;
    }
    for (auto* s : sweeps) {
      sim.vjp_batch(x, u, s->lambda, physics ? &s->propagated : nullptr, &s->mu);
      check_outputs("vjp_batch", s->mu, s->propagated, x.cols());
    }
  } else {
    for_each_sample([&](Index b, auto& t) {
      if (seeded) seed(b, t);
      t.x = x.col(b);
      t.u = u.col(b);
      for (auto* s : sweeps) {
        t.lambda_sample = s->lambda.col(b);
        sim.vjp(t.x, t.u, t.lambda_sample, physics ? &t.lambda_x : nullptr, &t.lambda_u);
        check_vjp_output(physics ? &t.lambda_x : nullptr, &t.lambda_u, t.x.size(), t.u.size());
        s->mu.col(b) = t.lambda_u;
        if (physics) s->propagated.col(b) = t.lambda_x;
      }
    });
  }
}

}  // namespace sbptt::detail
