#pragma once
// Work beside the calling thread on long-lived helper threads: the second thread of a tile (its
// second mesh strip, its Draco encoding beside the check of the drawn surface).
//
// Why not std::async: a thread started for each task was measured to stay on its starter's CPU.
// On the 2-core machines this runs on, a cold tile's two mesh strips then shared one core in
// 4 ms slices for most of the tile while the other core idled (scheduler trace of `terrabound
// serve`), and a z10 tile of N44W072 took 19 ms to mesh instead of 14. A helper that waits for
// work is woken onto an idle CPU instead.
//
// A task never waits for another task: when no helper is idle, a new one starts, so tasks that
// block on each other cannot deadlock. Helpers idle for a minute exit, except the first few. A
// job runs at the nice value of the thread that handed it over (the server's generation threads
// run at a lower priority, and the halves of their tiles on helpers with them).
#include <functional>
#include <future>
#include <memory>
#include <type_traits>
#include <utility>

namespace tb::tiler {

// Runs job on a helper thread, or on this one, before returning, when no thread can be started.
void run_on_helper(std::function<void()> job);

// The result of a task run beside this thread. Like the future of std::async, it waits for the
// task when it goes away unread, so what the task refers to outlives it even when the caller
// leaves by an exception.
template <typename Result> class Beside {
public:
    Beside() = default;
    explicit Beside(std::future<Result> future) : future_(std::move(future)) {}
    Beside(Beside&&) noexcept = default;
    Beside& operator=(Beside&& other) noexcept {
        wait();
        future_ = std::move(other.future_);
        return *this;
    }
    Beside(const Beside&) = delete;
    Beside& operator=(const Beside&) = delete;
    ~Beside() { wait(); }

    bool valid() const { return future_.valid(); }
    // The task's result, or its exception rethrown; once.
    Result get() { return future_.get(); }
    void wait() const {
        if (future_.valid()) {
            future_.wait();
        }
    }

private:
    std::future<Result> future_;
};

// task() on a helper thread.
template <typename Task> Beside<std::invoke_result_t<Task&>> beside(Task task) {
    using Result = std::invoke_result_t<Task&>;
    auto packaged = std::make_shared<std::packaged_task<Result()>>(std::move(task));
    Beside<Result> result(packaged->get_future());
    run_on_helper([packaged] { (*packaged)(); });
    return result;
}

} // namespace tb::tiler
