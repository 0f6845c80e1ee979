// ThreadPool::run_beside: the foreground always runs on the calling thread, an item never runs
// on the calling thread while the foreground does, an item that waits for the foreground is
// released whether it ran beside it or after it, every item runs exactly once, and exceptions
// (the foreground's first) come back to the caller after every item has finished; runs of
// different sizes in quick succession, and a pool being destroyed, never run an item again.
#include <catch2/catch.hpp>

#include <atomic>
#include <stdexcept>
#include <thread>
#include <vector>

#include "sbptt/core/parallel.hpp"

using sbptt::Index;
using sbptt::detail::ThreadPool;

TEST_CASE("run_beside: foreground on the caller, items beside it or after it, each once",
          "[core][parallel]") {
  for (const Index threads : {1, 2, 3}) {
    INFO("threads " << threads);
    ThreadPool pool(threads);
    const auto caller = std::this_thread::get_id();
    for (int round = 0; round < 200; ++round) {
      std::atomic<bool> foreground_running{false}, foreground_done{false};
      std::atomic<int> on_caller_during_foreground{0};
      std::vector<std::atomic<int>> runs(3);
      auto item = [&](Index i, Index) {
        if (std::this_thread::get_id() == caller && foreground_running.load())
          on_caller_during_foreground.fetch_add(1);
        while (!foreground_done.load()) std::this_thread::yield();  // waits for the foreground
        runs[static_cast<std::size_t>(i)].fetch_add(1);
      };
      std::thread::id foreground_thread;
      pool.run_beside(3, item, [&] {
        foreground_running = true;
        foreground_thread = std::this_thread::get_id();
        foreground_running = false;
        foreground_done = true;
      });
      REQUIRE(foreground_thread == caller);
      REQUIRE(on_caller_during_foreground.load() == 0);
      for (const auto& count : runs) REQUIRE(count.load() == 1);
    }
  }
}

TEST_CASE("run_beside: the foreground's exception comes back after the items have finished",
          "[core][parallel]") {
  for (const Index threads : {1, 2}) {
    INFO("threads " << threads);
    ThreadPool pool(threads);
    std::atomic<bool> released{false};
    std::atomic<int> finished{0};
    auto item = [&](Index, Index) {
      while (!released.load()) std::this_thread::yield();
      finished.fetch_add(1);
    };
    CHECK_THROWS_WITH(pool.run_beside(2, item,
                                      [&] {
                                        released = true;
                                        throw std::runtime_error("foreground failed");
                                      }),
                      "foreground failed");
    CHECK(finished.load() == 2);  // nothing still reads the caller's stack

    auto failing = [&](Index i, Index) {
      if (i == 1) throw std::runtime_error("item failed");
    };
    CHECK_THROWS_WITH(pool.run_beside(3, failing, [] {}), "item failed");
    int plain = 0;
    auto counting = [&](Index, Index) { ++plain; };
    pool.run(1, counting);  // the pool is usable afterwards
    CHECK(plain == 1);
  }
}

TEST_CASE("runs of different sizes in quick succession run every item exactly once",
          "[core][parallel]") {
  // A worker that has just finished the last item of a run may look at the pool again while
  // the caller is already writing the next run's size: it must never claim an item of the old
  // run with the new run's size or task (that ran an item twice, or let a run return before
  // its items were done). Small runs followed by larger ones make that window as wide as it
  // gets; ThreadSanitizer sees the race whether or not the count goes wrong.
  ThreadPool pool(2);
  std::vector<int> small(1), large(5);
  auto count_small = [&](Index i, Index) { ++small[static_cast<std::size_t>(i)]; };
  auto count_large = [&](Index i, Index) { ++large[static_cast<std::size_t>(i)]; };
  for (int round = 0; round < 20000; ++round) {
    small.assign(small.size(), 0);
    large.assign(large.size(), 0);
    pool.run_beside(1, count_small, [] {});
    pool.run(5, count_large);
    // Each item writes only its own counter; `run` returns after all of them.
    bool once = small[0] == 1;
    for (const int c : large) once = once && c == 1;
    if (!once) FAIL("round " << round << ": an item ran " << (small[0] == 1 ? "" : "in the "
                               "small run ") << "other than exactly once");
  }
  SUCCEED("20000 rounds");
}

TEST_CASE("a pool being destroyed never runs a finished run's task again", "[core][parallel]") {
  // The destructor wakes the workers to stop them; a worker still looking at the last run must
  // not take that wake-up for a new run of the old task (whose captures may be gone by then:
  // an engine's buffers die before its pool).
  std::atomic<int> late{0};
  std::atomic<bool> returned{false};
  auto task = [&](Index, Index) {
    if (returned.load()) late.fetch_add(1);
  };
  for (int round = 0; round < 20000; ++round) {
    returned = false;
    ThreadPool pool(3);
    pool.run(3, task);
    returned = true;
  }
  CHECK(late.load() == 0);
}
