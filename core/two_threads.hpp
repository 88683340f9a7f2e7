#pragma once
// Two halves of one job, on two threads or one after the other: the mesher's phases that split
// their work in two on a big grid (TriangulateOptions::threads). Each half must write only its
// own data, so that the result never depends on which runs first.
#include <cstddef>
#include <future>
#include <system_error>

namespace tb::core {

// Grids of this many samples and more split their work in two (never a 257 x 257 tile).
inline constexpr std::size_t kTwoThreadSamples = std::size_t{1} << 18;

// Runs first and second: second on a thread of its own when `two` (after first on this thread
// when no thread can be started), else after first. Returns when both have; an exception of
// either is rethrown (first's first).
template <typename First, typename Second> void run_both(bool two, First&& first, Second&& second) {
    std::future<void> other;
    if (two) {
        try {
            other = std::async(std::launch::async, [&second] { second(); });
        } catch (const std::system_error&) {
            // No thread to be had: the same work on this one.
        }
    }
    first();
    if (other.valid()) {
        other.get();
    } else {
        second();
    }
}

} // namespace tb::core
