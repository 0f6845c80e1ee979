#pragma once
/// \file What bench measures of the host itself, beside the epochs: the clock, the peak of a
/// matrix product, the cross-core round trip, the reads of another core's lines, and how much
/// slower copies of an epoch run at once are than one alone.
#include <algorithm>
#include <atomic>
#include <barrier>
#include <chrono>
#include <cstddef>
#include <exception>
#include <mutex>
#include <stdexcept>
#include <system_error>
#include <thread>
#include <utility>
#include <vector>

#include <sbptt/sbptt.hpp>

namespace bench {

using sbptt::Index;
using sbptt::Matrix;

inline double now_ms() {
  return std::chrono::duration<double, std::milli>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

/// Milliseconds that `work()` takes.
template <class Work>
double timed_ms(Work&& work) {
  const double start = now_ms();
  work();
  return now_ms() - start;
}

/// Best GFLOP/s of an n×n product on this thread (Eigen without threads: one core).
template <class S>
double measure_peak() {
  double best = 0;
  for (const Index n : {512, 768, 1024}) {
    const Matrix<S> a = Matrix<S>::Random(n, n), b = Matrix<S>::Random(n, n);
    Matrix<S> c(n, n);
    for (int repeat = 0; repeat < 4; ++repeat) {
      const double start = now_ms();
      c.noalias() = a * b;
      const double ms = now_ms() - start;
      best = std::max(best, 2.0 * static_cast<double>(n * n) * static_cast<double>(n) / (ms * 1e6));
    }
  }
  return best;
}

/// A thread running `work`, one of the `asked` threads of `what` (the caller's included), of
/// which `started` run already. Where the system will not start it (ulimit -u, a pids limit), a
/// ResourceError naming `what`, instead of std::thread's bare "Resource temporarily
/// unavailable".
template <class Work>
std::thread started_thread(const char* what, Index started, Index asked, Work&& work) {
  try {
    return std::thread(std::forward<Work>(work));
  } catch (const std::system_error& e) {
    throw sbptt::ResourceError(
        sbptt::detail::concat(what, ": ", sbptt::detail::threads_not_started(started, asked,
                                                                             e.what())));
  }
}

/// Waits until `flag` holds `value`, spinning, and yielding now and then so that it also ends on
/// a machine with one free core.
inline void spin_until(const std::atomic<int>& flag, int value) {
  for (int spins = 0; flag.load(std::memory_order_acquire) != value; ++spins)
    if (spins % 4096 == 4095) std::this_thread::yield();
}

/// Median over batches of the time of one round trip of a cache line between two threads,
/// each waiting for the other's store: the price of every hand-off between the engine's
/// threads. On the machine of docs/benchmark-runs.md (eleventh run) it swings between about 80
/// and 400 ns from one minute to the next, and the two-thread speed-ups swing with it, so
/// every row prints the round trip measured right after its threaded epochs. The first batch
/// is left out: it waits for the new thread to start, which took up to 16 ms there.
inline double cross_core_round_trip_ns() {
  constexpr int kBatches = 12;  // 11 kept: an odd count has one middle value
  constexpr int kTrips = 2000;  // per batch
  alignas(64) std::atomic<int> ball{0};
  std::thread partner = started_thread("the cross-core round trip", 1, 2, [&] {
    for (int i = 0; i < kBatches * kTrips; ++i) {
      spin_until(ball, 2 * i + 1);
      ball.store(2 * i + 2, std::memory_order_release);
    }
  });
  std::vector<double> ns;
  ns.reserve(kBatches);  // nothing to allocate while the partner runs: a throw would terminate
  for (int batch = 0; batch < kBatches; ++batch) {
    const double start = now_ms();
    for (int i = batch * kTrips; i < (batch + 1) * kTrips; ++i) {
      ball.store(2 * i + 1, std::memory_order_release);
      spin_until(ball, 2 * i + 2);
    }
    if (batch > 0) ns.push_back((now_ms() - start) * 1e6 / kTrips);
  }
  partner.join();
  std::nth_element(ns.begin(), ns.begin() + static_cast<std::ptrdiff_t>(ns.size() / 2), ns.end());
  return ns[ns.size() / 2];
}

/// How many times longer this thread takes to read 4 MiB that another thread has just written
/// than 4 MiB it wrote itself (one load a cache line, best of 5 reads each): about 1 when the
/// two threads' cores share their last-level cache, nearly the cost of a read from memory when
/// they do not. The 4 MiB are past a core's own caches (1 MiB of L2 on the machine of
/// docs/benchmark-runs.md) and well within a shared L3. The threads are not pinned, as the
/// engine's are not: about 1 can also mean that both ran on one core. On that machine a probe
/// of the same reads, its threads pinned, gave 0.73–1.74 while the round trip was mostly fast
/// (76–100 ns in 36 of 42 runs) and 2.26–3.12 while it was slow (366–799 ns), the other core's
/// lines then nearly as slow as memory's (twenty-second run): in its slow state the host runs
/// the two virtual cores where they share no cache.
inline double other_core_read_ratio() {
  constexpr std::size_t kLines = (std::size_t{4} << 20) / 64;
  constexpr int kReads = 5;
  constexpr std::size_t kPerLine = 64 / sizeof(long long);
  std::vector<long long> lines(kLines * kPerLine);
  alignas(64) std::atomic<int> turn{0};
  const auto write_all = [&](long long value) {
    for (std::size_t i = 0; i < lines.size(); ++i) lines[i] = value + static_cast<long long>(i);
  };
  long long sum = 0;  // stored below into a volatile, so that no load can be dropped
  const auto timed_read = [&] {
    const double start = now_ms();
    for (std::size_t line = 0; line < kLines; ++line) sum += lines[line * kPerLine];
    return now_ms() - start;
  };
  double other = 1e300, own = 1e300;
  std::thread writer = started_thread("the read of another core's lines", 1, 2, [&] {
    for (int r = 0; r < kReads; ++r) {
      spin_until(turn, 2 * r);
      write_all(r);
      turn.store(2 * r + 1, std::memory_order_release);
    }
  });
  for (int r = 0; r < kReads; ++r) {
    spin_until(turn, 2 * r + 1);
    other = std::min(other, timed_read());
    turn.store(2 * r + 2, std::memory_order_release);
  }
  writer.join();
  for (int r = 0; r < kReads; ++r) {
    write_all(r);
    own = std::min(own, timed_read());
  }
  volatile long long sink = sum;
  static_cast<void>(sink);
  return other / own;
}

/// How many times as long the slowest of `copies` threads takes for an epoch when each runs
/// one of its own at once, as one thread takes alone: best of `repeats` rounds of each, after a
/// warm-up, the alone and together rounds taken in turn so that both see the machine of the
/// same minute (its speed drifts: docs/benchmark-runs-intel.md). The copies share nothing, so
/// this is what the host gives that many busy cores, whatever the engine does: the same epoch
/// split perfectly over the threads would be at best copies / ratio times faster. `copy(rounds)`
/// runs on each copy's thread: it builds that copy's work there (its buffers then belong to
/// that thread, as the engine's do) and hands `rounds` a callable that runs one epoch. The
/// threads wait for a round in a `std::barrier`, asleep, so that the copy that runs alone has
/// its core and no other thread spinning beside it. A copy that fails (or a thread the system
/// will not start) ends the rounds of all: each copy that leaves before its last round drops
/// out of the barrier, so that none waits for it, and the first failure is rethrown here once
/// every thread is joined (a joinable std::thread left behind, or an exception leaving one,
/// would terminate the program).
template <class Copy>
double concurrent_copies_ratio(Index copies, int repeats, Copy&& copy) {
  const auto rounds = static_cast<std::size_t>(repeats);
  std::vector<double> alone(rounds);
  std::vector<std::vector<double>> together(static_cast<std::size_t>(copies),
                                            std::vector<double>(rounds));
  std::barrier round_start(static_cast<std::ptrdiff_t>(copies));
  std::atomic<bool> abandoned{false};
  std::exception_ptr failure;
  std::mutex failure_mutex;
  const auto run_copy = [&](Index c) {
    bool finished = false;  // every round waited for
    try {
      copy([&](auto&& epoch) {
        epoch();  // warm-up: buffers sized, pages touched
        for (std::size_t round = 0; round < rounds; ++round) {
          round_start.arrive_and_wait();
          if (abandoned) return;
          if (c == 0) alone[round] = timed_ms(epoch);
          round_start.arrive_and_wait();
          if (abandoned) return;
          together[static_cast<std::size_t>(c)][round] = timed_ms(epoch);
        }
        finished = true;
      });
      if (!finished && !abandoned)  // its times would read 0
        throw std::logic_error(sbptt::detail::concat(
            "concurrent_copies_ratio: copy ", c, " returned without running its rounds"));
    } catch (...) {
      const std::lock_guard lock(failure_mutex);
      if (!failure) failure = std::current_exception();
      abandoned = true;
    }
    if (!finished) round_start.arrive_and_drop();
  };
  std::vector<std::thread> others;
  others.reserve(static_cast<std::size_t>(copies - 1));
  try {
    for (Index c = 1; c < copies; ++c)
      others.push_back(started_thread("the copies of an epoch run at once", c, copies,
                                      [&run_copy, c] { run_copy(c); }));
  } catch (...) {
    abandoned = true;
    // The copies never started and this thread's own leave the barrier.
    for (auto missing = copies - static_cast<Index>(others.size()); missing > 0; --missing)
      round_start.arrive_and_drop();
    for (auto& thread : others) thread.join();
    throw;
  }
  run_copy(0);
  for (auto& thread : others) thread.join();
  if (failure) std::rethrow_exception(failure);
  double best_together = 1e300;
  for (std::size_t round = 0; round < rounds; ++round) {
    double slowest = 0;
    for (const auto& times : together) slowest = std::max(slowest, times[round]);
    best_together = std::min(best_together, slowest);
  }
  return best_together / *std::min_element(alone.begin(), alone.end());
}

}  // namespace bench
