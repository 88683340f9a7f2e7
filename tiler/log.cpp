#include "tiler/log.hpp"

#include <atomic>
#include <condition_variable>
#include <cstdio>
#include <ctime>
#include <mutex>
#include <string>
#include <thread>
#include <utility>

namespace tb::log {
namespace {
std::atomic<int> g_level{static_cast<int>(Level::Info)};
std::mutex g_mutex;

const char* name(Level level) {
    switch (level) {
    case Level::Debug:
        return "debug";
    case Level::Info:
        return "info ";
    case Level::Warn:
        return "warn ";
    case Level::Error:
        return "error";
    case Level::Off:
        break;
    }
    return "?";
}
} // namespace

void set_level(Level l) {
    g_level.store(static_cast<int>(l));
}
Level level() {
    return static_cast<Level>(g_level.load());
}

bool parse_level(std::string_view n, Level& out) {
    static constexpr std::pair<std::string_view, Level> kNames[] = {
        {"debug", Level::Debug},
        {"info", Level::Info},
        {"warn", Level::Warn},
        {"error", Level::Error},
        {"off", Level::Off},
    };
    for (const auto& [text, value] : kNames) {
        if (n == text) {
            out = value;
            return true;
        }
    }
    return false;
}

namespace {

// One line, as it is written: timestamp, level, the message with any newline folded.
std::string format(Level l, std::string_view message) {
    const std::time_t now = std::time(nullptr);
    std::tm utc{};
    gmtime_r(&now, &utc);
    char stamp[32];
    std::strftime(stamp, sizeof stamp, "%Y-%m-%dT%H:%M:%SZ", &utc);
    std::string line;
    line.reserve(message.size() + 40);
    line.append(stamp).append(" ").append(name(l)).append(" ");
    for (char c : message) {
        line.push_back(c == '\n' || c == '\r' ? ' ' : c);
    }
    line.push_back('\n');
    return line;
}

// Lines waiting for the writer thread, at most this many.
constexpr std::size_t kMaxQueuedLines = 10000;

// The queue of write_queued and its writer thread, started on first use. g_mutex orders every
// write to stderr; the queue's own mutex is only ever held for a move of the pending text.
class Queue {
public:
    void push(std::string line) {
        {
            std::lock_guard lock(mutex_);
            if (lines_ >= kMaxQueuedLines) {
                ++dropped_;
                return;
            }
            pending_ += line;
            ++lines_;
            if (!writer_.joinable()) {
                writer_ = std::thread([this] { run(); });
            }
        }
        cv_.notify_one();
    }

    // Writes what is pending; the caller holds g_mutex.
    void drain_locked() {
        std::string text;
        std::size_t dropped = 0;
        {
            std::lock_guard lock(mutex_);
            text.swap(pending_);
            lines_ = 0;
            std::swap(dropped, dropped_);
        }
        if (dropped > 0) {
            text += format(Level::Warn,
                           std::to_string(dropped) +
                               " log lines dropped: stderr is not keeping up with the requests");
        }
        if (!text.empty()) {
            std::fwrite(text.data(), 1, text.size(), stderr);
            std::fflush(stderr);
        }
    }

    ~Queue() {
        {
            std::lock_guard lock(mutex_);
            stop_ = true;
        }
        cv_.notify_one();
        if (writer_.joinable()) {
            writer_.join();
        }
        std::lock_guard lock(g_mutex);
        drain_locked();
    }

private:
    void run() {
        for (;;) {
            {
                std::unique_lock lock(mutex_);
                cv_.wait(lock, [this] { return stop_ || lines_ > 0 || dropped_ > 0; });
                if (stop_) {
                    return;
                }
            }
            std::lock_guard lock(g_mutex);
            drain_locked();
        }
    }

    std::mutex mutex_;
    std::condition_variable cv_;
    std::string pending_;
    std::size_t lines_ = 0;
    std::size_t dropped_ = 0;
    bool stop_ = false;
    std::thread writer_;
};

Queue& queue() {
    static Queue q;
    return q;
}

bool enabled(Level l) {
    return static_cast<int>(l) >= g_level.load() && l != Level::Off;
}

} // namespace

void write(Level l, std::string_view message) {
    if (!enabled(l)) {
        return;
    }
    const std::string line = format(l, message);
    std::lock_guard lock(g_mutex);
    queue().drain_locked(); // queued lines first: the output stays in order
    std::fwrite(line.data(), 1, line.size(), stderr);
    std::fflush(stderr);
}

void write_queued(Level l, std::string_view message) {
    if (!enabled(l)) {
        return;
    }
    queue().push(format(l, message));
}

void flush() {
    std::lock_guard lock(g_mutex);
    queue().drain_locked();
}

} // namespace tb::log
