#include "tiler/log.hpp"

#include <atomic>
#include <cstdio>
#include <ctime>
#include <mutex>
#include <string>

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

void write(Level l, std::string_view message) {
    if (static_cast<int>(l) < g_level.load() || l == Level::Off) {
        return;
    }
    std::time_t now = std::time(nullptr);
    std::tm utc{};
    gmtime_r(&now, &utc);
    char stamp[32];
    std::strftime(stamp, sizeof stamp, "%Y-%m-%dT%H:%M:%SZ", &utc);
    // One event, one line: fold any newline inside the message.
    std::string line;
    line.reserve(message.size() + 40);
    line.append(stamp).append(" ").append(name(l)).append(" ");
    for (char c : message) {
        line.push_back(c == '\n' || c == '\r' ? ' ' : c);
    }
    line.push_back('\n');
    std::lock_guard lock(g_mutex);
    std::fwrite(line.data(), 1, line.size(), stderr);
    std::fflush(stderr);
}

} // namespace tb::log
