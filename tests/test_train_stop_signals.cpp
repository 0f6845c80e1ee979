// StopSignals against the kernel's own record of signal dispositions (sigaction) and signals
// actually raised; the task programs and train_own_scene test it end to end (a stopped run's
// rerun ends bit for bit as one uninterrupted run, tests/programs/test_program_outputs.cpp).
#include <catch2/catch.hpp>
#include <signal.h>
#include <unistd.h>
#include "sbptt/train/stop_signals.hpp"

namespace {

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

}  // namespace

TEST_CASE("stop signals: the first signal is noted and gets its default action back",
          "[train]") {
  for (const int signal : {SIGINT, SIGTERM}) {
    INFO(sbptt::signal_name(signal));
    REQUIRE(std::signal(signal, SIG_DFL) != SIG_ERR);
    {
      const sbptt::StopSignals stop("test");
      CHECK_FALSE(stop.requested());
      CHECK(disposition(signal) != SIG_DFL);
      quietly([&] { REQUIRE(::raise(signal) == 0); });
      CHECK(stop.requested());
      CHECK(stop.signal() == signal);
      CHECK(disposition(signal) == SIG_DFL);  // a second one would end the process
    }
    CHECK(disposition(SIGINT) == SIG_DFL);
    CHECK(disposition(SIGTERM) == SIG_DFL);
  }
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
