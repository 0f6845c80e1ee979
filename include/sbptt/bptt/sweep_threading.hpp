#pragma once
/// \file Whether the reverse sweeps of an `Engine` with several threads hand work from one core
/// to the other at every step, and the timed decision that chooses it (`SweepThreading`).
#include <algorithm>

#include "sbptt/core/types.hpp"

namespace sbptt {

/// How an `Engine` with several threads (`Engine::set_threads`) runs a batch whose sweep meets
/// the other thread at every step: a lone sweep (`reverse`) whose per-sample loops are split or
/// whose parameter products go to a second thread, and the combined update's pair when its
/// sweeps share one backward pass (one control) and split its steps. Such a sweep pays only
/// while a cache line crosses from one core to the other quickly, and on a shared host that
/// time can change about fivefold within a minute (docs/benchmark-runs.md, fiftieth run). A
/// batch run alone has its forward pass on the calling thread too: a rollout in parts leaves
/// half of the trajectory in the other core's cache for the sweep to read. `evaluate` and a
/// batch whose two sweeps run apart (more than one control) use the threads in every case:
/// their threads meet once per call. Results are the same bits whichever way a batch runs.
enum class SweepThreading {
  /// Both ways timed in turn, the faster kept, and timed again after a few hundred batches.
  Timed,
  Always,  ///< every such batch on the threads
  Never,   ///< every such batch on the calling thread alone, as with one thread
};

/// How many of an engine's batches of one kind ran each way (`Engine::sweep_tally`).
struct SweepTally {
  Index threaded = 0;  ///< on the threads
  Index alone = 0;     ///< on the calling thread
};

namespace detail {

/// `SweepThreading::Timed` for one kind of sweep: a probing runs `probes` batches each way,
/// alternately and the threaded way first, then keeps the way with the least time per sample
/// (the best of its probes) for `sweeps_between` batches; then it probes again. The engine
/// times a batch from its forward pass to the end of its sweep. The threaded way goes first
/// because its buffers include the other's, so that both are sized by the first batches at a
/// shape. A batch whose sweep throws is not counted.
class SweepThreadingDecision {
public:
  static constexpr int probes = 3;
  static constexpr int sweeps_between = 256;

  explicit SweepThreadingDecision(SweepThreading policy = SweepThreading::Timed)
      : policy_(policy) {}

  /// Whether the next batch runs on the threads.
  [[nodiscard]] bool next_threaded() const {
    if (policy_ != SweepThreading::Timed) return policy_ == SweepThreading::Always;
    return probing() ? sweeps_ % 2 == 0 : threaded_;
  }

  /// Counts a finished batch that took `ns_per_sample` (read only while probing).
  void finished(double ns_per_sample) {
    ++(next_threaded() ? tally_.threaded : tally_.alone);
    if (policy_ != SweepThreading::Timed) return;
    if (probing()) {
      const bool threaded = next_threaded();
      double& best = best_ns_[threaded ? 1 : 0];
      best = sweeps_ < 2 ? ns_per_sample : std::min(best, ns_per_sample);
      if (sweeps_ + 1 == 2 * probes) threaded_ = best_ns_[1] < best_ns_[0];
    }
    if (++sweeps_ == 2 * probes + sweeps_between) sweeps_ = 0;
  }

  [[nodiscard]] const SweepTally& tally() const { return tally_; }

private:
  [[nodiscard]] bool probing() const { return sweeps_ < 2 * probes; }

  SweepThreading policy_;
  SweepTally tally_;
  int sweeps_ = 0;          ///< since the last probing began
  bool threaded_ = true;    ///< the last probing's choice
  double best_ns_[2] = {};  ///< per sample, alone and threaded, in the current probing
};

}  // namespace detail
}  // namespace sbptt
