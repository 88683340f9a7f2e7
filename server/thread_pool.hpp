#pragma once
// A fixed set of threads draining a FIFO of jobs: the connection loops' request workers and
// the tile service's generation threads. Admission, if any, is the caller's business.
#include <condition_variable>
#include <deque>
#include <functional>
#include <mutex>
#include <thread>
#include <utility>
#include <vector>

namespace tb::server {

class ThreadPool {
public:
    // `threads` threads (at least 1); each runs `on_start` first, if given (e.g. to lower its
    // priority).
    explicit ThreadPool(int threads, std::function<void()> on_start = {}) {
        for (int i = 0; i < std::max(1, threads); ++i) {
            threads_.emplace_back([this, on_start] {
                if (on_start) {
                    on_start();
                }
                run();
            });
        }
    }
    ~ThreadPool() { join(); }
    ThreadPool(const ThreadPool&) = delete;
    ThreadPool& operator=(const ThreadPool&) = delete;

    void submit(std::function<void()> job) {
        {
            std::lock_guard<std::mutex> lock(mutex_);
            jobs_.push_back(std::move(job));
        }
        cv_.notify_one();
    }

    // Lets every job already submitted run, then joins the threads. Safe to call more than once.
    void join() {
        {
            std::lock_guard<std::mutex> lock(mutex_);
            stopping_ = true;
        }
        cv_.notify_all();
        for (auto& t : threads_) {
            if (t.joinable()) {
                t.join();
            }
        }
    }

private:
    void run() {
        for (;;) {
            std::function<void()> job;
            {
                std::unique_lock<std::mutex> lock(mutex_);
                cv_.wait(lock, [this] { return stopping_ || !jobs_.empty(); });
                if (jobs_.empty()) {
                    return; // stopping, and every queued job has run
                }
                job = std::move(jobs_.front());
                jobs_.pop_front();
            }
            job();
        }
    }

    std::mutex mutex_;
    std::condition_variable cv_;
    std::deque<std::function<void()>> jobs_;
    bool stopping_ = false;
    std::vector<std::thread> threads_;
};

} // namespace tb::server
