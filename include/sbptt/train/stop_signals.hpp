#pragma once
/// \file Stopping a run cleanly on SIGINT or SIGTERM. While a `StopSignals` lives, the first of
/// those signals is noted and announced on stderr at once (an epoch of a large scene may take
/// minutes, and silence would read as a signal lost), and the signal gets its default action
/// back, so that a second one ends the process at once. `requested()` as
/// `RunCallbacks::should_stop` then ends the run after its current epoch (`RunEnd::Requested`)
/// with that epoch's log row, a checkpoint and the parameters written (docs/training.md,
/// "Stopping on a signal").
///
/// A signal the process was started ignoring stays ignored: a non-interactive shell starts a
/// background job (`program &`) with SIGINT ignored, and that choice is its starter's (make
/// and Python keep it too). A handler reaches only static storage, so one `StopSignals` lives
/// at a time.
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <csignal>
#include <cstdio>
#include <initializer_list>
#include <vector>

#include "sbptt/core/error.hpp"

namespace sbptt {

namespace detail_stop_signals {

inline volatile std::sig_atomic_t caught = 0;  ///< the signal that came, or 0
inline bool alive = false;                     ///< a StopSignals exists

/// The notice of SIGINT (0) and SIGTERM (1), composed before the handlers are installed:
/// a handler may only write(2) it.
inline char notice[2][256];
inline std::size_t notice_size[2];

extern "C" inline void note(int signal) {
  caught = signal;
  std::signal(signal, SIG_DFL);
  const int saved_errno = errno;  // of the code the signal interrupted
  const int k = signal == SIGINT ? 0 : 1;
  [[maybe_unused]] const auto written = ::write(2, notice[k], notice_size[k]);
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

/// "SIGINT" or "SIGTERM".
[[nodiscard]] inline const char* signal_name(int signal) {
  return signal == SIGINT ? "SIGINT" : "SIGTERM";
}

class StopSignals {
 public:
  /// Installs the handlers of SIGINT and SIGTERM (of those not ignored now). The notice a
  /// signal prints starts with `program`. Throws `InvalidArgument` if another `StopSignals`
  /// lives.
  explicit StopSignals(const char* program) {
    namespace s = detail_stop_signals;
    detail::require(!s::alive, "StopSignals: another one lives; expected one at a time");
    s::alive = true;
    s::caught = 0;
    for (const int k : {0, 1}) {
      const char* name = signal_name(k == 0 ? SIGINT : SIGTERM);
      const int size = std::snprintf(s::notice[k], sizeof s::notice[k],
                                     "%s: %s: stopping after the current epoch, which keeps its "
                                     "work; a second %s stops at once\n",
                                     program, name, name);
      s::notice_size[k] =
          size < 0 ? 0 : std::min(static_cast<std::size_t>(size), sizeof s::notice[k] - 1);
    }
    installed_ = signals_not_ignored({SIGINT, SIGTERM});
    for (const int signal : installed_) std::signal(signal, s::note);
  }

  /// Gives the signals their default action back.
  ~StopSignals() {
    for (const int signal : installed_) std::signal(signal, SIG_DFL);
    detail_stop_signals::alive = false;
  }

  StopSignals(const StopSignals&) = delete;
  StopSignals& operator=(const StopSignals&) = delete;

  /// The signal that came (SIGINT or SIGTERM), or 0.
  [[nodiscard]] int signal() const { return detail_stop_signals::caught; }
  [[nodiscard]] bool requested() const { return signal() != 0; }

 private:
  std::vector<int> installed_;
};

}  // namespace sbptt
