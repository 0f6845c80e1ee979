#pragma once
/// \file Whether the engine splits a per-sample loop of a step over its threads, timed on the
/// loop's first runs (`ForkDecision`). Implementation detail of `sbptt::Engine`.
#include <algorithm>
#include <chrono>
#include <vector>

#include "sbptt/core/parallel.hpp"
#include "sbptt/core/types.hpp"
#include "sbptt/core/unroll.hpp"

namespace sbptt::detail {

/// Whether a per-sample loop is worth splitting over threads. A fork costs about a microsecond
/// when the workers are awake, so a cheap simulator (cart pole: tens of ns per sample) runs its
/// loop on one thread; an expensive one (a quantum step done per sample: about a microsecond)
/// is split. The first `probes` runs are serial and timed; the best time decides from then on.
/// Only speed depends on the decision: every sample is computed the same way either way.
class ForkDecision {
public:
  static constexpr int probes = 4;
  /// Split loops of 4 µs of serial work or more: a fork costs about a microsecond.
  static constexpr double default_threshold_ns = 4000;

  /// \param threshold_ns split loops whose serial time is at least this (0: always split)
  explicit ForkDecision(double threshold_ns = default_threshold_ns)
      : threshold_ns_(threshold_ns) {}

  [[nodiscard]] bool probing() const { return runs_ < probes; }
  [[nodiscard]] bool fork() const { return !probing() && best_ns_ >= threshold_ns_; }
  [[nodiscard]] bool splits_every_loop() const { return threshold_ns_ == 0; }
  void record(double ns) {
    best_ns_ = runs_ == 0 ? ns : std::min(best_ns_, ns);
    ++runs_;
  }

  /// Calls f(b, scratch) for every sample b of the batch: as items of a parallel run on `pool`
  /// when `parallel`, a pool exists and the loop is worth it, else in order on this thread
  /// (timed while still probing). `scratch` has one entry per worker of `pool`.
  template <class Scratch, class F>
  void for_samples(ThreadPool* pool, Index batch, std::vector<Scratch>& scratch, bool parallel,
                   F&& f) {
    if (pool != nullptr && parallel && batch > 1) {
      if (fork()) {
        auto task = [&](Index b, Index worker) {
          one_sample(f, b, scratch[static_cast<std::size_t>(worker)]);
        };
        pool->run(batch, task);
        return;
      }
      if (probing()) {
        const auto start = std::chrono::steady_clock::now();
        for (Index b = 0; b < batch; ++b) one_sample(f, b, scratch[0]);
        record(std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - start)
                   .count());
        return;
      }
    }
    for (Index b = 0; b < batch; ++b) one_sample(f, b, scratch[0]);
  }

private:
  /// f(b, scratch) in one machine copy (SBPTT_ONE_COPY) for the three loops above.
  template <class F, class Scratch>
  SBPTT_ONE_COPY static void one_sample(F& f, Index b, Scratch& scratch) {
    f(b, scratch);
  }

  double threshold_ns_;
  int runs_ = 0;
  double best_ns_ = 0;
};

}  // namespace sbptt::detail
