#pragma once
/// \file The way an `Engine` with several threads runs its current training batch: on the
/// threads, or on the calling thread alone. The decision of the sweep that follows
/// (`SweepThreading`) chooses it at the forward pass, and the batch is timed from there to the
/// end of that sweep.
#include <chrono>
#include <optional>

#include "sbptt/bptt/fork_decision.hpp"
#include "sbptt/bptt/sweep_threading.hpp"
#include "sbptt/core/types.hpp"

namespace sbptt::detail {

/// The sweeps that `SweepThreading` decides: a lone sweep (`reverse`), the shared-seed pair.
enum class SweepKind { Lone, Pair };

/// How the next lone sweep would use the threads: `handoff` its parameter products, or its
/// per-sample loops split; `meets_threads` if either, once the loops are timed.
struct LonePlan {
  bool handoff = false, meets_threads = false;
};

/// The `LonePlan` of an engine whose VJP loops are timed by `vjp_loops`, with `has_pool`
/// threads and `has_handoff` a hand-off of parameter products.
template <bool IsBatchSimulator>
[[nodiscard]] LonePlan lone_plan(const ForkDecision& vjp_loops, bool has_pool,
                                 bool has_handoff) {
  // A BatchSimulator's VJPs are never split (only its loss seeds, and those only when told to
  // split every loop); other simulators' loops are split once timed and found worth it.
  const bool loops_timed = IsBatchSimulator || !vjp_loops.probing();
  const bool split_loops = IsBatchSimulator ? vjp_loops.splits_every_loop() : vjp_loops.fork();
  // Only where the loops are not split: the second thread then has nothing better to do than
  // the parameter products.
  const bool handoff = has_handoff && loops_timed && !split_loops;
  return {handoff, has_pool && loops_timed && (split_loops || handoff)};
}

/// The current batch's way and the two decisions (lone sweeps, shared-seed pairs) that choose
/// it. A rollout in parts leaves half of the trajectory in the other core's cache, which a
/// sweep on the calling thread alone would then read across, so the forward pass goes the
/// sweep's way (docs/design.md).
class BatchThreading {
public:
  explicit BatchThreading(SweepThreading policy = SweepThreading::Timed)
      : lone_(policy), pair_(policy) {}

  [[nodiscard]] SweepTally tally() const {
    return {lone_.tally().threaded + pair_.tally().threaded,
            lone_.tally().alone + pair_.tally().alone};
  }

  /// Whether the lone decision chooses the way of a lone batch: when its sweep would meet the
  /// other thread at every step, and under `Never` in every case.
  [[nodiscard]] bool decides_lone(bool meets_threads) const {
    return meets_threads || lone_.policy() == SweepThreading::Never;
  }

  /// At the forward pass of a batch of `samples`, to be followed by a sweep of kind `kind`;
  /// `decided` if that kind's decision chooses the batch's way (else it runs on the threads).
  /// The batch is timed from here to `finish`, but for the first of its kind at a size, which
  /// runs on the threads untimed: each kind's threaded buffers are its own (the hand-off's,
  /// the split's), and sizing them sizes those of the calling thread's way too.
  /// \return whether the batch runs on the threads.
  bool begin(SweepKind kind, bool decided, Index samples) {
    SweepThreadingDecision& decision = decision_of(kind);
    threaded_ = !decided || decision.next_threaded(decision.first_at(samples));
    way_of_ = decided ? std::optional<SweepKind>(kind) : std::nullopt;
    end_awaited_ = decided;
    start_ = std::chrono::steady_clock::now();
    return threaded_;
  }

  /// The way of the current batch: of its forward pass, its loss and a shared-seed pair's sweep.
  [[nodiscard]] bool threaded() const { return threaded_; }

  /// Whether a lone sweep runs on the threads: the way of its forward pass if the lone
  /// decision chose that, else (its loops were not timed at the forward pass, its batch did not
  /// meet the threads, or it was a pair's) the lone decision's next way where it decides, and
  /// on the threads where it does not.
  [[nodiscard]] bool lone_sweep_threaded(bool meets_threads) const {
    if (way_of_ == SweepKind::Lone) return threaded_;
    return !decides_lone(meets_threads) || lone_.next_threaded();
  }

  /// Whether the decision of kind `kind` awaits the end of the current batch; true at most
  /// once per batch, so that a sweep that throws leaves its batch uncounted.
  bool claim_end(SweepKind kind) {
    const bool awaited = end_awaited_ && way_of_ == kind;
    end_awaited_ = false;
    return awaited;
  }

  /// The end of the current batch of `samples`, to the decision of kind `kind`: its time per
  /// sample, or its way and its size for the first at that size (out of the schedule).
  void finish(SweepKind kind, Index samples) {
    SweepThreadingDecision& decision = decision_of(kind);
    if (decision.first_at(samples)) {  // none has finished at this size since `begin` either
      decision.finished_first_at(samples, threaded_);
      return;
    }
    const std::chrono::duration<double, std::nano> took =
        std::chrono::steady_clock::now() - start_;
    decision.finished(took.count() / static_cast<double>(samples));
  }

private:
  SweepThreadingDecision& decision_of(SweepKind kind) {
    return kind == SweepKind::Lone ? lone_ : pair_;
  }

  SweepThreadingDecision lone_, pair_;
  bool threaded_ = true;             ///< the way of the current batch
  std::optional<SweepKind> way_of_;  ///< the decision that chose it, if one did
  bool end_awaited_ = false;         ///< that decision still awaits the batch's end
  std::chrono::steady_clock::time_point start_;
};

}  // namespace sbptt::detail
