// StopSignals against the kernel's own record of signal dispositions (sigaction) and signals
// actually raised; the task programs and train_own_scene test it end to end (a stopped run's
// rerun ends bit for bit as one uninterrupted run, tests/programs/test_program_outputs.cpp).
#include <catch2/catch.hpp>
#include <fcntl.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>
#include <csignal>
#include <ctime>
#include <utility>
#include "sbptt/train/stop_signals.hpp"

namespace {

constexpr int stop_kinds[] = {SIGINT, SIGTERM, SIGHUP, SIGXCPU};

/// The handler the process has for `signal` now.
void (*disposition(int signal))(int) {
  struct sigaction current {};
  REQUIRE(sigaction(signal, nullptr, &current) == 0);
  return current.sa_handler;
}

/// Runs `body` with stderr into /dev/null (the notice a signal prints), then restores it.
template <class Body>
void quietly(Body&& body) {
  const int saved = ::dup(2);
  REQUIRE(saved >= 0);
  std::FILE* null = std::fopen("/dev/null", "w");
  REQUIRE(null != nullptr);
  ::dup2(::fileno(null), 2);
  body();
  ::dup2(saved, 2);
  ::close(saved);
  std::fclose(null);
}

/// The wait status of a child that, its stderr into /dev/null and the stop signals at their
/// default, makes a `StopSignals` and exits with `body(stop)`: what a signal does to a process
/// is seen from outside it.
template <class Body>
int status_of_child(Body&& body) {
  const pid_t child = ::fork();
  REQUIRE(child >= 0);
  if (child == 0) {
    const int null = ::open("/dev/null", O_WRONLY);
    ::dup2(null, 2);
    for (const int kind : stop_kinds) std::signal(kind, SIG_DFL);
    const sbptt::StopSignals stop("child");
    ::_exit(body(stop));
  }
  int status = 0;
  REQUIRE(::waitpid(child, &status, 0) == child);
  return status;
}

}  // namespace

TEST_CASE("stop signals: the first signal is noted and gets its default action back",
          "[train]") {
  // SIGHUP (a closed terminal, a dropped ssh connection) and SIGXCPU (a soft CPU-time limit,
  // which batch systems send before their kill) ended a run at once with nothing saved.
  for (const int signal : stop_kinds) {
    INFO(sbptt::signal_name(signal));
    for (const int kind : stop_kinds)
      REQUIRE(std::signal(kind, SIG_DFL) != SIG_ERR);  // not Catch's own handlers
    {
      const sbptt::StopSignals stop("test");
      CHECK_FALSE(stop.requested());
      for (const int kind : stop_kinds) CHECK(disposition(kind) != SIG_DFL);
      quietly([&] { REQUIRE(::raise(signal) == 0); });
      CHECK(stop.requested());
      CHECK(stop.signal() == signal);
      // A second one, of any kind, would end the process; SIGXCPU repeats by itself.
      for (const int kind : stop_kinds)
        CHECK(disposition(kind) == (kind == SIGXCPU ? SIG_IGN : SIG_DFL));
    }
    for (const int kind : stop_kinds) CHECK(disposition(kind) == SIG_DFL);
  }
}

TEST_CASE("stop signals: a second signal of the other kind ends the process at once",
          "[train]") {
  // Ctrl-C, then a SIGTERM from a timeout or a scheduler: found by a review, the SIGTERM was
  // caught again and replaced the SIGINT. In a child, which the second signal must kill.
  for (const auto& signals : {std::pair{SIGINT, SIGTERM}, std::pair{SIGTERM, SIGINT},
                              std::pair{SIGHUP, SIGINT}, std::pair{SIGXCPU, SIGHUP}}) {
    // Named copies, not a structured binding: clang 14 cannot capture a binding in a lambda.
    const int first = signals.first;
    const int second = signals.second;
    INFO(sbptt::signal_name(first) << " then " << sbptt::signal_name(second));
    const int status = status_of_child([&](const sbptt::StopSignals& stop) {
      ::raise(first);
      ::raise(second);
      return stop.signal() == first ? 100 : 101;  // alive: the second was caught
    });
    CHECK(WIFSIGNALED(status));
    CHECK((WIFSIGNALED(status) ? WTERMSIG(status) : -WEXITSTATUS(status)) == second);
  }
}

TEST_CASE("stop signals: past a soft CPU-time limit the epoch under way still ends", "[train]") {
  // The kernel sends SIGXCPU at the soft limit and again every CPU second after it: with its
  // default action back after the first, the second killed the run about a second later, its
  // epoch unfinished and nothing saved. A child with a soft limit of 1 s (the hard one at
  // 30 s) spins 2.5 CPU seconds past it, as an epoch would.
  const int status = status_of_child([](const sbptt::StopSignals& stop) {
    const rlimit limit{1, 30};
    if (::setrlimit(RLIMIT_CPU, &limit) != 0) return 102;
    const auto cpu_seconds = [] {
      timespec t{};
      ::clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
      return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
    };
    volatile double sink = 0;
    while (!stop.requested() && cpu_seconds() < 20) sink = sink + 1;
    const double noted = cpu_seconds();
    while (cpu_seconds() < noted + 2.5) sink = sink + 1;
    return stop.signal() == SIGXCPU ? 0 : 101;
  });
  INFO((WIFSIGNALED(status) ? "killed by signal " : "exit ")
       << (WIFSIGNALED(status) ? WTERMSIG(status) : WEXITSTATUS(status)));
  CHECK((WIFEXITED(status) && WEXITSTATUS(status) == 0));
}

extern "C" void count_signal(int /*signal*/) {}

TEST_CASE("stop signals: the end gives back the handlers there were before", "[train]") {
  // A host program's own handler (an interpreter's, a test framework's) must survive a run.
  REQUIRE(std::signal(SIGINT, count_signal) != SIG_ERR);
  REQUIRE(std::signal(SIGTERM, SIG_DFL) != SIG_ERR);
  {
    const sbptt::StopSignals stop("test");
    CHECK(disposition(SIGINT) != count_signal);
  }
  CHECK(disposition(SIGINT) == count_signal);
  CHECK(disposition(SIGTERM) == SIG_DFL);
  REQUIRE(std::signal(SIGINT, SIG_DFL) != SIG_ERR);
}

TEST_CASE("stop signals: a signal ignored before stays ignored; one lives at a time", "[train]") {
  REQUIRE(std::signal(SIGINT, SIG_IGN) != SIG_ERR);
  REQUIRE(std::signal(SIGTERM, SIG_DFL) != SIG_ERR);
  {
    const sbptt::StopSignals stop("test");
    CHECK(disposition(SIGINT) == SIG_IGN);
    CHECK(disposition(SIGTERM) != SIG_DFL);
    REQUIRE(::raise(SIGINT) == 0);
    CHECK_FALSE(stop.requested());
    CHECK_THROWS_AS(sbptt::StopSignals("another"), sbptt::InvalidArgument);
    CHECK(disposition(SIGTERM) != SIG_DFL);  // the refused one changed nothing
  }
  CHECK(disposition(SIGINT) == SIG_IGN);
  CHECK(disposition(SIGTERM) == SIG_DFL);
  const sbptt::StopSignals next("test");  // the first one's end lets another live
  CHECK_FALSE(next.requested());
  REQUIRE(std::signal(SIGINT, SIG_DFL) != SIG_ERR);
}
