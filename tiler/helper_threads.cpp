#include "tiler/helper_threads.hpp"

#include <sys/resource.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <deque>
#include <mutex>
#include <optional>
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

// The calling thread's nice value (Linux keeps one per thread), or nullopt.
std::optional<int> own_nice() {
    errno = 0;
    const int nice = getpriority(PRIO_PROCESS, static_cast<id_t>(gettid()));
    if (nice == -1 && errno != 0) {
        return std::nullopt;
    }
    return nice;
}

} // namespace

void run_on_helper(std::function<void()> job) {
    // The job runs at its submitter's nice value: the server's generation threads yield to the
    // threads that answer requests, and the half of a tile that runs on a helper must too.
    const std::optional<int> nice = own_nice();
    Helpers::get().run([nice, job = std::move(job)] {
        if (nice && own_nice() != nice) {
            // Raising a thread's priority back may be refused (no CAP_SYS_NICE): it then runs
            // at the lower one it has.
            setpriority(PRIO_PROCESS, static_cast<id_t>(gettid()), *nice);
        }
        job();
    });
}

} // namespace tb::tiler
