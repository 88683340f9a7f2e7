// The helper threads a tile's second thread of work runs on (tiler/helper_threads.hpp).
#include <doctest/doctest.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <mutex>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "tiler/helper_threads.hpp"

#include <sys/resource.h>
#include <unistd.h>

using namespace tb::tiler;

TEST_CASE("beside runs a task on another thread and hands back its result or its exception") {
    const std::thread::id here = std::this_thread::get_id();
    Beside<std::thread::id> where = beside([] { return std::this_thread::get_id(); });
    CHECK(where.get() != here);
    Beside<std::string> fails = beside([]() -> std::string { throw std::runtime_error("no"); });
    CHECK_THROWS_WITH_AS(fails.get(), "no", std::runtime_error);
}

TEST_CASE("tasks that wait for each other all run at once: a helper starts when none is idle") {
    // Each task waits until all have started; with fewer helpers than tasks this would hang
    // (bounded here by the deadline, so a failure shows as a count below kTasks).
    constexpr int kTasks = 6;
    std::mutex m;
    std::condition_variable cv;
    int started = 0;
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
    std::vector<Beside<int>> tasks;
    for (int k = 0; k < kTasks; ++k) {
        tasks.push_back(beside([&] {
            std::unique_lock<std::mutex> lock(m);
            ++started;
            cv.notify_all();
            cv.wait_until(lock, deadline, [&] { return started == kTasks; });
            return started;
        }));
    }
    for (Beside<int>& t : tasks) {
        CHECK(t.get() == kTasks);
    }
    // The helpers are free again: more work runs, on threads other than this one.
    for (int round = 0; round < 3; ++round) {
        CHECK(beside([] { return 1 + 1; }).get() == 2);
    }
}

TEST_CASE("an unread result waits for its task when it goes away, so the task's data outlives "
          "it") {
    std::atomic<bool> done{false};
    {
        Beside<void> slow = beside([&done] {
            std::this_thread::sleep_for(std::chrono::milliseconds(50));
            done = true;
        });
    } // leaves unread, as when the caller throws
    CHECK(done.load());
    // Moving a new task over a pending one waits for the pending one first.
    std::atomic<bool> first{false};
    Beside<void> slot = beside([&first] {
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
        first = true;
    });
    slot = beside([] {});
    CHECK(first.load());
    slot.get();
}

TEST_CASE("a job runs at the nice value of the thread that handed it over") {
    // From a thread at nice 15 (lowering one's own priority is always allowed).
    int seen = 0;
    std::thread low([&seen] {
        REQUIRE(setpriority(PRIO_PROCESS, static_cast<id_t>(gettid()), 15) == 0);
        seen = beside([] { return getpriority(PRIO_PROCESS, static_cast<id_t>(gettid())); }).get();
    });
    low.join();
    CHECK(seen == 15);
}
