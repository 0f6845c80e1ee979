#pragma once
/// \file Stopping a run cleanly on SIGINT, SIGTERM, SIGHUP or SIGXCPU: Ctrl-C, a kill or a
/// scheduler's end of a job, a closed terminal or dropped ssh connection, a soft CPU-time limit
/// (which batch systems send before their kill). While a `StopSignals` lives, the first of
/// those signals is noted and announced on stderr at once (an epoch of a large scene may take
/// minutes, and silence would read as a signal lost), and SIGINT, SIGTERM and SIGHUP get their
/// default action back, so that a second one, of any kind, ends the process at once. SIGXCPU is
/// ignored from then on: past the soft limit the kernel sends it again every CPU second, and
/// its default would end the epoch that the first one let finish (the hard limit still ends
/// the process). `requested()` as `RunCallbacks::should_stop` then ends the run after its
/// current epoch (`RunEnd::Requested`) with that epoch's log row, a checkpoint and the
/// parameters written (docs/training.md, "Stopping on a signal"). Its end gives back the
/// handlers there were before.
///
/// A signal the process was started ignoring stays ignored: a non-interactive shell starts a
/// background job (`program &`) with SIGINT ignored, and that choice is its starter's (make
/// and Python keep it too). A handler reaches only static storage, so one `StopSignals` lives
/// at a time.
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <csignal>
#include <cstdio>
#include <initializer_list>
#include <iterator>
#include <vector>

#include "sbptt/core/error.hpp"

namespace sbptt {

namespace detail_stop_signals {

constexpr int handled[] = {SIGINT, SIGTERM, SIGHUP, SIGXCPU};
constexpr int kinds = static_cast<int>(std::size(handled));

// Atomics, not volatile: the handler may run on any of the library's threads.
static_assert(std::atomic<int>::is_always_lock_free && std::atomic<bool>::is_always_lock_free,
              "a signal handler needs lock-free atomics");
inline std::atomic<int> caught{0};                   ///< the first signal that came, or 0
inline std::atomic<bool> installed[kinds] = {};  ///< per `handled`
inline std::atomic<bool> alive{false};               ///< a StopSignals exists

/// The notice of each of `handled`, composed before the handlers are installed: a handler may
/// only write(2) it.
inline char notice[kinds][256];
inline std::size_t notice_size[kinds];

extern "C" inline void note(int signal) {
  const int saved_errno = errno;  // of the code the signal interrupted
  // sigaction, not std::signal: C++ promises the latter's safety for the signal handled alone.
  struct sigaction after {};
  sigemptyset(&after.sa_mask);
  for (int k = 0; k < kinds; ++k) {
    if (!installed[k]) continue;
    after.sa_handler = handled[k] == SIGXCPU ? SIG_IGN : SIG_DFL;
    sigaction(handled[k], &after, nullptr);
  }
  int none = 0;
  if (caught.compare_exchange_strong(none, signal)) {
    for (int k = 0; k < kinds; ++k) {
      if (handled[k] != signal) continue;
      [[maybe_unused]] const auto written = ::write(2, notice[k], notice_size[k]);
    }
  }
  errno = saved_errno;
}

}  // namespace detail_stop_signals

/// Of `signals`, those this process does not ignore as it stands.
[[nodiscard]] inline std::vector<int> signals_not_ignored(std::initializer_list<int> signals) {
  std::vector<int> kept;
  for (const int signal : signals) {
    struct sigaction current {};
    if (sigaction(signal, nullptr, &current) != 0 || current.sa_handler != SIG_IGN)
      kept.push_back(signal);
  }
  return kept;
}

/// Whether `signal` is one that a `StopSignals` answers (a program that has one then exits
/// with 128 + it, its work saved).
[[nodiscard]] inline bool is_stop_signal(int signal) {
  return std::ranges::find(detail_stop_signals::handled, signal) !=
         std::end(detail_stop_signals::handled);
}

/// "SIGINT", "SIGTERM", "SIGHUP", "SIGXCPU"; "a signal" for any other.
[[nodiscard]] inline const char* signal_name(int signal) {
  switch (signal) {
    case SIGINT: return "SIGINT";
    case SIGTERM: return "SIGTERM";
    case SIGHUP: return "SIGHUP";
    case SIGXCPU: return "SIGXCPU";
    default: return "a signal";
  }
}

class StopSignals {
 public:
  /// Installs the handlers of SIGINT, SIGTERM, SIGHUP and SIGXCPU (of those not ignored now).
  /// The notice a signal prints starts with `program`. Throws `InvalidArgument` if another
  /// `StopSignals` lives.
  explicit StopSignals(const char* program) {
    namespace s = detail_stop_signals;
    bool none = false;
    detail::require(s::alive.compare_exchange_strong(none, true),
                    "StopSignals: another one lives; expected one at a time");
    s::caught = 0;
    struct sigaction action {};
    action.sa_handler = s::note;
    sigemptyset(&action.sa_mask);
    for (const int signal : s::handled) sigaddset(&action.sa_mask, signal);  // one at a time
    for (int k = 0; k < s::kinds; ++k) {
      const char* name = signal_name(s::handled[k]);
      const int size =
          s::handled[k] == SIGXCPU
              ? std::snprintf(s::notice[k], sizeof s::notice[k],
                              "%s: SIGXCPU: past the soft CPU-time limit; stopping after the "
                              "current epoch, which keeps its work, unless the hard limit "
                              "comes first\n",
                              program)
              : std::snprintf(s::notice[k], sizeof s::notice[k],
                              "%s: %s: stopping after the current epoch, which keeps its work; "
                              "a second %s stops at once\n",
                              program, name, name);
      s::notice_size[k] =
          size < 0 ? 0 : std::min(static_cast<std::size_t>(size), sizeof s::notice[k] - 1);
      s::installed[k] = sigaction(s::handled[k], nullptr, &previous_[k]) == 0 &&
                        previous_[k].sa_handler != SIG_IGN;
    }
    for (int k = 0; k < s::kinds; ++k)
      if (s::installed[k]) sigaction(s::handled[k], &action, nullptr);
  }

  /// Gives back the handlers there were before.
  ~StopSignals() {
    namespace s = detail_stop_signals;
    for (int k = 0; k < s::kinds; ++k) {
      if (s::installed[k]) sigaction(s::handled[k], &previous_[k], nullptr);
      s::installed[k] = false;
    }
    s::alive = false;
  }

  StopSignals(const StopSignals&) = delete;
  StopSignals& operator=(const StopSignals&) = delete;
  StopSignals(StopSignals&&) = delete;
  StopSignals& operator=(StopSignals&&) = delete;

  /// The first signal that came (SIGINT, SIGTERM, SIGHUP or SIGXCPU), or 0.
  [[nodiscard]] int signal() const { return detail_stop_signals::caught; }
  [[nodiscard]] bool requested() const { return signal() != 0; }

 private:
  struct sigaction previous_[detail_stop_signals::kinds] {};
};

}  // namespace sbptt
