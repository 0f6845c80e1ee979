// StepSplit (bptt/step_split.hpp), the split of the shared-seed pair's recordings between
// the sweeping thread and a second one: the pattern of the tasks (StepShare) by enumeration;
// every task's backward pass runs exactly once and before its products, the products are added
// exactly once and in task order, only after the sweep has recorded the task's μ, whichever
// thread does the work; the sweep runs a backward pass it waits for that the second thread has
// not begun; the sweep finishes alone when the second thread never starts, stops
// waiting when the second thread fails, and a sweep that gives up stops the second thread.
#include <catch2/catch.hpp>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <future>
#include <stdexcept>
#include <thread>
#include <vector>

#include "sbptt/bptt/step_split.hpp"

using sbptt::Index;

namespace {

using Split = sbptt::detail::StepSplit<int, double>;

/// What happened to each task, from either thread.
struct Record {
  explicit Record(Index tasks) : prepared(static_cast<std::size_t>(tasks)) {}
  std::vector<std::atomic<int>> prepared;  ///< backward passes run per task
  std::vector<Index> added;                ///< tasks in the order their products were added
  std::atomic<int> added_before_swept{0}, added_before_prepared{0};
};

/// The sweep's side: records each task's μ, then waits for its backward pass; then waits for
/// every product. False if it stopped because the second thread failed.
template <class Prepare, class Add>
bool sweep(Split& split, Prepare& prepare, Add& add) {
  for (Index task = 0; task < split.tasks; ++task) {
    split.swept.store(task + 1, std::memory_order_release);
    if (!split.wait_prepared(task, prepare, add)) return false;
  }
  return split.wait_added(add);
}

}  // namespace

TEST_CASE("step split: each task prepared once, added once and in order, on one or two threads",
          "[bptt][threads]") {
  for (const bool second_thread : {false, true}) {
    for (const Index steps : {0, 1, 2, 7, 40}) {
      INFO("second thread " << second_thread << ", steps " << steps);
      for (int round = 0; round < (second_thread ? 100 : 1); ++round) {
        Split split;
        split.reset(steps);
        REQUIRE(split.tasks == sbptt::detail::StepShare::tasks_before(steps));
        Record record(split.tasks);
        auto prepare = [&](Index task, Split::Slot& slot) {
          record.prepared[static_cast<std::size_t>(task)].fetch_add(1);
          slot.adjoints = static_cast<int>(task);
        };
        auto add = [&](Index task, Split::Slot& slot) {
          if (split.swept.load() <= task) record.added_before_swept.fetch_add(1);
          if (slot.adjoints != task) record.added_before_prepared.fetch_add(1);
          record.added.push_back(task);  // under the split's lock
        };
        std::thread second;
        if (second_thread) second = std::thread([&] { split.keep_working(prepare, add); });
        CHECK(sweep(split, prepare, add));
        if (second.joinable()) second.join();
        std::vector<Index> in_order;
        for (Index task = 0; task < split.tasks; ++task) {
          CHECK(record.prepared[static_cast<std::size_t>(task)].load() == 1);
          in_order.push_back(task);
        }
        CHECK(record.added == in_order);
        CHECK(record.added_before_swept.load() == 0);
        CHECK(record.added_before_prepared.load() == 0);
      }
    }
  }
}

TEST_CASE("step split: 4 of every 7 recordings are tasks, spread evenly, numbered in order",
          "[bptt][threads]") {
  using Share = sbptt::detail::StepShare;
  // The pattern as docs/design.md lists it, repeated every 7 recordings.
  const std::vector<Index> first_period = {1, 3, 5, 6};
  Index tasks = 0, since_task = 0;
  for (Index recording = 0; recording < 7 * 60; ++recording) {
    INFO("recording " << recording);
    const bool listed = std::find(first_period.begin(), first_period.end(), recording % 7) !=
                        first_period.end();
    CHECK(Share::is_task(recording) == listed);
    if (recording % 7 == 0) CHECK(tasks == 4 * (recording / 7));
    CHECK(Share::tasks_before(recording) == tasks);
    if (Share::is_task(recording)) {
      CHECK(Share::recording_of(tasks) == recording);
      ++tasks;
      since_task = 0;
    } else {
      ++since_task;
      CHECK(since_task < 2);  // never two of the sweep's own in a row
    }
  }
}

TEST_CASE("step split: a task counts as prepared after its slot has passed to a later task",
          "[bptt][threads]") {
  // The second thread may add a task and run the backward pass of the task that reuses its
  // slot before the sweep looks at it.
  Split split;
  split.reset(2 * (Split::ring_size + 2));
  auto nothing = [](Index, Split::Slot&) {};
  for (Index task = 0; task < Split::ring_size; ++task) REQUIRE(split.try_preparing(nothing));
  CHECK_FALSE(split.try_preparing(nothing));  // the ring is full
  split.swept.store(1);
  REQUIRE(split.try_adding(nothing));
  REQUIRE(split.try_preparing(nothing));  // task ring_size, into task 0's slot
  CHECK(split.is_prepared(0));
  CHECK(split.is_prepared(Split::ring_size));
  CHECK_FALSE(split.is_prepared(Split::ring_size + 1));
}

TEST_CASE("step split: the sweep runs the backward pass it waits for when the second thread, "
          "though started, has not begun it", "[bptt][threads]") {
  // The second thread may be busy adding earlier tasks' products; the sweep would idle.
  Split split;
  split.reset(20);
  split.started.store(true);
  std::atomic<int> prepared{0};
  auto prepare = [&](Index, Split::Slot&) { prepared.fetch_add(1); };
  auto nothing = [](Index, Split::Slot&) {};
  auto waiting = std::async(std::launch::async,
                            [&] { return split.wait_prepared(0, prepare, nothing); });
  const bool returned =
      waiting.wait_for(std::chrono::seconds(10)) == std::future_status::ready;
  if (!returned) split.failed.store(true);  // ends a wait that no one would serve
  CHECK(returned);
  CHECK(waiting.get() == returned);
  CHECK(prepared.load() == 1);
  CHECK(split.is_prepared(0));
  CHECK(split.claimed.load() == 1);
}

TEST_CASE("step split: the sweep stops waiting when the second thread fails, and a sweep that "
          "gives up stops the second thread", "[bptt][threads]") {
  Split split;
  split.reset(20);
  auto throwing = [](Index, Split::Slot&) { throw std::runtime_error("planted failure"); };
  auto nothing = [](Index, Split::Slot&) {};
  // The second thread claims task 0 and throws before the sweep starts.
  CHECK_THROWS_WITH(split.keep_working(throwing, nothing), "planted failure");
  CHECK(split.failed.load());
  CHECK_FALSE(sweep(split, nothing, nothing));

  split.reset(20);
  split.abandoned.store(true);
  split.keep_working(nothing, nothing);  // returns at once, nothing claimed
  CHECK(split.claimed.load() == 0);
}
