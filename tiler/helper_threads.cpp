#include "tiler/helper_threads.hpp"

#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <deque>
#include <mutex>
#include <system_error>
#include <thread>

namespace tb::tiler {
namespace {

// Helpers kept however long they idle; the others exit after kIdleExit without work.
constexpr std::size_t kKeep = 4;
constexpr std::chrono::seconds kIdleExit{60};

class Helpers {
public:
    // Never destroyed: detached helpers may still wait on it while the process exits.
    static Helpers& get() {
        static Helpers* helpers = new Helpers;
        return *helpers;
    }

    void run(std::function<void()> job) {
        std::unique_lock<std::mutex> lock(mutex_);
        jobs_.push_back(std::move(job));
        if (jobs_.size() <= idle_) {
            cv_.notify_one();
            return;
        }
        ++threads_;
        try {
            std::thread([this] { work(); }).detach();
        } catch (const std::system_error&) {
            // No thread to be had: run it here (still queued last: the lock was held).
            --threads_;
            std::function<void()> own = std::move(jobs_.back());
            jobs_.pop_back();
            lock.unlock();
            own();
        }
    }

private:
    void work() {
        std::unique_lock<std::mutex> lock(mutex_);
        for (;;) {
            ++idle_;
            const bool got = cv_.wait_for(lock, kIdleExit, [this] { return !jobs_.empty(); });
            --idle_;
            if (!got) {
                if (threads_ > kKeep) {
                    --threads_;
                    return;
                }
                continue;
            }
            std::function<void()> job = std::move(jobs_.front());
            jobs_.pop_front();
            lock.unlock();
            job(); // a packaged task: its exception goes to its future
            lock.lock();
        }
    }

    std::mutex mutex_;
    std::condition_variable cv_;
    std::deque<std::function<void()>> jobs_;
    std::size_t idle_ = 0;    // helpers waiting for a job
    std::size_t threads_ = 0; // helpers alive
};

} // namespace

void run_on_helper(std::function<void()> job) {
    Helpers::get().run(std::move(job));
}

} // namespace tb::tiler
