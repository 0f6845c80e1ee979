// reproduce: child processes (spawned in their own process group, dying with the runner) and
// the signals that interrupt a sweep.
#pragma once

#include <fcntl.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <fstream>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include <sbptt/core/atomic_file.hpp>
#include <sbptt/train/stop_signals.hpp>

#include "text.hpp"

namespace reproduce {

inline volatile std::sig_atomic_t interrupted = 0;
/// Signals received: the first lets the running task programs end their epoch, the second
/// kills them (local_executor.hpp).
inline volatile std::sig_atomic_t signals_received = 0;
extern "C" void on_signal(int signal_number) {
  interrupted = signal_number;
  signals_received = signals_received + 1;
}

/// SIGINT, SIGTERM and SIGHUP stop the sweep, but one the runner was started ignoring
/// (sbptt/train/stop_signals.hpp): `nohup reproduce ... &` must outlive a hangup.
inline void install_signal_handlers() {
  struct sigaction action {};
  action.sa_handler = on_signal;
  sigemptyset(&action.sa_mask);
  for (int s : sbptt::signals_not_ignored({SIGINT, SIGTERM, SIGHUP}))
    sigaction(s, &action, nullptr);
}

/// Forks and execs argv[0] with stdin from /dev/null and stdout + stderr into `log_fd` (or
/// inherited when -1). The child gets its own process group (a terminal's Ctrl-C reaches
/// only the runner, which then stops its children) and dies with the runner.
inline pid_t spawn(const std::vector<std::string>& argv, int log_fd, bool search_path = false,
                   int error_fd = -1) {
  std::vector<char*> pointers;
  for (const auto& a : argv) pointers.push_back(const_cast<char*>(a.c_str()));
  pointers.push_back(nullptr);
  const int null_fd = sbptt::detail::open_above_standard_streams("/dev/null", O_RDONLY | O_CLOEXEC);
  const pid_t parent = ::getpid();
  const pid_t pid = ::fork();
  if (pid == 0) {
    // Only async-signal-safe calls until exec.
    ::setpgid(0, 0);
    ::prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (::getppid() != parent) ::_exit(127);  // the runner died before prctl took effect
    // exec passes an ignored signal on: whatever the runner was started ignoring, its SIGTERM
    // must stop the child, and the SIGPIPE and SIGXFSZ it ignores itself (write_signals.hpp)
    // are the child's own business (a task program that is a script expects `| head` to work).
    struct sigaction action {};
    action.sa_handler = SIG_DFL;
    for (int s : {SIGINT, SIGTERM, SIGHUP, SIGXCPU, SIGPIPE, SIGXFSZ})
      ::sigaction(s, &action, nullptr);
    // dup2 onto the same number leaves close-on-exec set: clear it instead.
    const auto onto = [](int from, int to) {
      if (from != to) ::dup2(from, to);
      else ::fcntl(to, F_SETFD, ::fcntl(to, F_GETFD) & ~FD_CLOEXEC);
    };
    if (null_fd >= 0) onto(null_fd, 0);
    if (log_fd >= 0) {
      onto(log_fd, 1);
      onto(error_fd >= 0 ? error_fd : log_fd, 2);
    }
    if (search_path) ::execvp(pointers[0], pointers.data());
    else ::execv(pointers[0], pointers.data());
    const char message[] = "reproduce: cannot execute the program\n";
    [[maybe_unused]] const auto ignored = ::write(2, message, sizeof message - 1);
    ::_exit(127);
  }
  if (null_fd >= 0) ::close(null_fd);
  return pid;
}

/// Runs a command to completion; returns its exit code (-1 when it did not exit normally).
inline int run_command(const std::vector<std::string>& argv, bool quiet) {
  int log_fd = -1;
  if (quiet) log_fd = sbptt::detail::open_above_standard_streams("/dev/null", O_WRONLY | O_CLOEXEC);
  const pid_t pid = spawn(argv, log_fd, true);
  if (log_fd >= 0) ::close(log_fd);
  if (pid < 0) return -1;
  if (interrupted) ::kill(pid, SIGTERM);  // the signal came before the wait it would interrupt
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0) {
    if (errno != EINTR) return -1;
    if (interrupted) ::kill(pid, SIGTERM);
  }
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

inline std::string describe_status(int status) {
  if (WIFEXITED(status)) return concat("exit code ", WEXITSTATUS(status));
  if (WIFSIGNALED(status)) return concat("killed by signal ", WTERMSIG(status));
  return "ended";
}

/// The signal that stopped a task program, or 0: the one that killed it, or one of
/// `StopSignals` (SIGINT, SIGTERM, SIGHUP, SIGXCPU) when it ended on it with exit code 128 + the
/// signal, after the epoch in which it came and with its checkpoint written (docs/programs.md).
inline int stopping_signal(int status) {
  if (WIFSIGNALED(status)) return WTERMSIG(status);
  if (!WIFEXITED(status)) return 0;
  const int signal = WEXITSTATUS(status) - 128;
  return sbptt::is_stop_signal(signal) ? signal : 0;
}

inline bool is_executable(const fs::path& path) {
  return ::access(path.c_str(), X_OK) == 0 && fs::is_regular_file(path);
}

/// The standard output of a command run to completion (stderr discarded), or "" when it
/// could not run.
inline std::string output_of(const std::vector<std::string>& argv) {
  int ends[2];
  if (::pipe2(ends, O_CLOEXEC) != 0) return {};
  const int null_fd = sbptt::detail::open_above_standard_streams("/dev/null", O_WRONLY | O_CLOEXEC);
  const pid_t pid = spawn(argv, ends[1], false, null_fd);
  ::close(ends[1]);
  if (null_fd >= 0) ::close(null_fd);
  std::string text;
  char buffer[4096];
  ssize_t got = 0;
  while ((got = ::read(ends[0], buffer, sizeof buffer)) != 0) {
    if (got > 0) text.append(buffer, static_cast<std::size_t>(got));
    else if (errno != EINTR) break;
  }
  ::close(ends[0]);
  int status = 0;
  while (pid > 0 && ::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  return text;
}

/// Whether a task program resumes runs from `--checkpoint FILE` (its --help lists the flag).
/// Asked once per program.
inline bool supports_checkpoints(const fs::path& program) {
  static std::map<fs::path, bool> known;
  const auto found = known.find(program);
  if (found != known.end()) return found->second;
  const bool supported =
      output_of({program.string(), "--help"}).find("--checkpoint ") != std::string::npos;
  known[program] = supported;
  return supported;
}

/// `program` as execvp finds it: a path when it has a '/', else a name on PATH.
inline bool can_execute(const std::string& program) {
  if (program.find('/') != std::string::npos) return is_executable(program);
  const char* path = std::getenv("PATH");
  for (const auto& dir : split(path ? path : "/usr/bin:/bin", ':'))
    if (is_executable(fs::path(dir.empty() ? "." : dir) / program)) return true;
  return false;
}

/// This program's own file, absolute.
inline fs::path own_executable(const char* argv0) {
  std::error_code error;
  const fs::path self = fs::read_symlink("/proc/self/exe", error);
  if (!error) return self;
  return fs::absolute(argv0);
}

inline std::string tail_of(const fs::path& log, std::size_t count) {
  const auto lines = split(read_text(log), '\n');
  std::string text;
  std::size_t shown = 0;
  for (auto it = lines.rbegin(); it != lines.rend() && shown < count; ++it) {
    if (it->empty()) continue;
    text = "    " + *it + "\n" + text;
    ++shown;
  }
  return text;
}

}  // namespace reproduce
