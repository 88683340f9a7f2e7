#pragma once
// The one logger: one line per event, to stderr, with a UTC timestamp and a level.
//   2026-11-23T11:40:02Z info  serving http://127.0.0.1:8080/
#include <string_view>

namespace tb::log {

enum class Level { Debug = 0, Info = 1, Warn = 2, Error = 3, Off = 4 };

void set_level(Level level);
Level level();
bool parse_level(std::string_view name, Level& out); // "debug" | "info" | "warn" | "error" | "off"

void write(Level level, std::string_view message); // thread-safe; whole lines only

// The same line, written by a background thread instead of the caller: for the access log of
// the HTTP server, whose connection loops must never wait on a slow stderr. Lines keep their
// order among themselves and come out before any later write(); past 10,000 waiting lines they
// are dropped, and a warning says how many. Written out at exit at the latest.
void write_queued(Level level, std::string_view message);

// Writes every queued line now (before printing to stderr directly).
void flush();

inline void debug(std::string_view m) {
    write(Level::Debug, m);
}
inline void info(std::string_view m) {
    write(Level::Info, m);
}
inline void warn(std::string_view m) {
    write(Level::Warn, m);
}
inline void error(std::string_view m) {
    write(Level::Error, m);
}

} // namespace tb::log
