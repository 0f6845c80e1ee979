#pragma once
/// \file Whether the reverse sweeps of an `Engine` with several threads hand work from one core
/// to the other at every step, and the timed decision that chooses it (`SweepThreading`).
#include <algorithm>
#include <string>
#include <string_view>

#include "sbptt/core/error.hpp"
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
/// pair whose sweeps run apart (they share no backward pass) use the threads in every case:
/// their threads meet once per call. Results are the same bits whichever way a batch runs.
enum class SweepThreading {
  /// 3 batches on the threads, then 3 alone, timed; the faster way kept, and timed again after
  /// 8 batches, then after twice as many each time the choice holds, up to 256. The first batch
  /// of each kind at a batch size runs on the threads, untimed: the buffers of that way include
  /// those of the other, so that it sizes both.
  Timed,
  Always,  ///< every such batch on the threads
  /// Every batch of `forward` and `reverse`, and of a pair that shares its backward pass, on
  /// the calling thread alone, its per-sample loops too, as with one thread.
  Never,
};

/// "timed", "always" or "never".
[[nodiscard]] inline std::string to_string(SweepThreading way) {
  switch (way) {
    case SweepThreading::Timed: return "timed";
    case SweepThreading::Always: return "always";
    case SweepThreading::Never: return "never";
  }
  throw InvalidArgument(detail::concat("SweepThreading with value ", static_cast<int>(way),
                                       " is not one of timed, always, never"));
}

/// Inverse of `to_string`: accepts exactly "timed", "always", "never"; anything else throws
/// `InvalidArgument` naming it.
[[nodiscard]] inline SweepThreading parse_sweep_threading(std::string_view text) {
  if (text == "timed") return SweepThreading::Timed;
  if (text == "always") return SweepThreading::Always;
  if (text == "never") return SweepThreading::Never;
  throw InvalidArgument(detail::concat("sweep threading \"", text, "\" is not recognised; ",
                                       "expected one of timed, always, never"));
}

/// How many of an engine's batches ran each way (`Engine::sweep_tally`).
struct SweepTally {
  Index threaded = 0;  ///< on the threads
  Index alone = 0;     ///< on the calling thread
};

namespace detail {

/// `SweepThreading::Timed` for one kind of sweep: a probing runs `probes` batches on the
/// threads, then `probes` on the calling thread, then keeps the way with the least time per
/// sample (the best of its probes) for the next `shortest_between` batches; then it probes
/// again. Each probing that keeps the previous one's way doubles the batches until the next,
/// up to `longest_between`; one that changes it goes back to the shortest. A probing can be
/// misled by a few slow batches (an engine's first probing has timed the threads at 1.76
/// times their time one probing later, docs/design.md): the short first interval lets the
/// next probing undo that early, and the longest keeps the probes' cost small in a long run.
/// The engine times a batch from its forward pass to the end of its sweep. The threaded probes
/// come in a row so that only the first of them meets workers that slept through batches run
/// alone (`ThreadPool`'s workers sleep when idle), and the best of three drops that one.
class SweepThreadingDecision {
public:
  static constexpr int probes = 3;
  static constexpr int shortest_between = 8;
  static constexpr int longest_between = 256;

  explicit SweepThreadingDecision(SweepThreading policy = SweepThreading::Timed)
      : policy_(policy) {}

  [[nodiscard]] SweepThreading policy() const { return policy_; }

  /// Whether the next batch runs on the threads; a batch that is `first_at_size` does when
  /// timed, and is then left out of the schedule (`finished_first_at`).
  [[nodiscard]] bool next_threaded(bool first_at_size = false) const {
    if (policy_ != SweepThreading::Timed) return policy_ == SweepThreading::Always;
    return first_at_size || (probing() ? batches_ < probes : threaded_);
  }

  /// Counts a finished batch of the schedule that took `ns_per_sample` (read only while
  /// probing).
  void finished(double ns_per_sample) {
    const bool threaded = next_threaded();
    ++(threaded ? tally_.threaded : tally_.alone);
    if (policy_ != SweepThreading::Timed) return;
    if (probing()) {
      double& best = best_ns_[threaded ? 1 : 0];
      best = batches_ % probes == 0 ? ns_per_sample : std::min(best, ns_per_sample);
      if (batches_ + 1 == 2 * probes) choose(best_ns_[1] < best_ns_[0]);
    }
    if (++batches_ == 2 * probes + between_) batches_ = 0;
  }

  /// Counts the first batch of this kind at `samples`, which ran outside the schedule,
  /// `threaded` or not, and notes its size. Only a batch whose sweep ended comes here: one whose
  /// forward pass or sweep threw, or that no sweep followed, may have sized nothing, so the
  /// next one is still the first.
  void finished_first_at(Index samples, bool threaded) {
    samples_ = samples;
    ++(threaded ? tally_.threaded : tally_.alone);
  }

  /// Whether no batch of this kind has finished at `samples` since one finished at another
  /// size.
  [[nodiscard]] bool first_at(Index samples) const { return samples != samples_; }

  [[nodiscard]] const SweepTally& tally() const { return tally_; }

private:
  [[nodiscard]] bool probing() const { return batches_ < 2 * probes; }

  void choose(bool threaded) {
    between_ = threaded == threaded_ ? std::min(2 * between_, longest_between) : shortest_between;
    threaded_ = threaded;
  }

  SweepThreading policy_;
  SweepTally tally_;
  Index samples_ = 0;       ///< the size of the last first batch that finished (0: none)
  int batches_ = 0;         ///< of the schedule, since the last probing began
  bool threaded_ = true;    ///< the last probing's choice
  /// Batches from the last probing's end to the next; half the shortest before the first
  /// probing, so that the first ends at the shortest whichever way it chooses.
  int between_ = shortest_between / 2;
  double best_ns_[2] = {};  ///< per sample, alone and threaded, in the current probing
};

}  // namespace detail
}  // namespace sbptt
