#pragma once
// A program that catches a signal to stop cleanly leaves alone one it was started ignoring:
// a non-interactive shell starts a background job (`program &`) with SIGINT ignored, `nohup`
// starts one with SIGHUP ignored, and that choice is its starter's (as make and Python do).
#include <signal.h>

#include <initializer_list>
#include <vector>

namespace sbptt::examples {

/// Of `signals`, those this process does not ignore as it stands.
inline std::vector<int> not_ignored(std::initializer_list<int> signals) {
  std::vector<int> kept;
  for (const int signal : signals) {
    struct sigaction current {};
    if (sigaction(signal, nullptr, &current) != 0 || current.sa_handler != SIG_IGN)
      kept.push_back(signal);
  }
  return kept;
}

}  // namespace sbptt::examples
