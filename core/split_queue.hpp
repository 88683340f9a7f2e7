#pragma once
// The split agent's queue (Lu & Yun §3.3, "triangle with largest # of error points"): every
// live triangle with error points, once. An indexed binary heap: a triangle's entry is updated
// in place when its stats change and leaves when it has no error point left, so the heap holds
// no stale entry and is never larger than the set of triangles still to split.
#include <cstdint>
#include <vector>

#include "core/memory.hpp"
#include "core/mesh.hpp"

namespace tb::core {

class SplitQueue {
public:
    bool empty() const { return heap_.empty(); }

    // Room for triangles numbered below n, all queued at once, without moving (memory.hpp).
    void reserve(std::size_t n) {
        heap_.reserve(n);
        pos_.reserve(n);
    }

    // The triangle to split next: most error points, then the largest share of error points
    // among its samples, then the largest total error, then the lowest index. The order is
    // total, so the choice does not depend on the heap's history.
    Index top() const { return heap_.front().t; }

    // Inserts t or updates its entry.
    void set(Index t, std::int64_t error_points, double fraction, double total_error) {
        if (pos_.size() <= t) {
            pos_.resize(static_cast<std::size_t>(t) + t / 2 + 1, 0);
        }
        const Entry e{error_points, fraction, total_error, t};
        std::size_t i = pos_[t];
        if (i == 0) {
            heap_.push_back(e);
            i = heap_.size();
        } else {
            heap_[i - 1] = e;
        }
        pos_[t] = static_cast<std::uint32_t>(i);
        sift_down(sift_up(i - 1));
    }

    // Removes t's entry, if any.
    void erase(Index t) {
        if (t >= pos_.size() || pos_[t] == 0) {
            return;
        }
        const std::size_t i = pos_[t] - 1;
        pos_[t] = 0;
        const Entry last = heap_.back();
        heap_.pop_back();
        if (i < heap_.size()) {
            heap_[i] = last;
            pos_[last.t] = static_cast<std::uint32_t>(i + 1);
            sift_down(sift_up(i));
        }
    }

    void clear() {
        heap_.clear();
        pos_.clear();
    }

private:
    struct Entry {
        std::int64_t error_points;
        double fraction;
        double total_error;
        Index t;
    };

    // a goes before b.
    static bool first(const Entry& a, const Entry& b) {
        if (a.error_points != b.error_points) {
            return a.error_points > b.error_points;
        }
        if (a.fraction != b.fraction) {
            return a.fraction > b.fraction;
        }
        if (a.total_error != b.total_error) {
            return a.total_error > b.total_error;
        }
        return a.t < b.t;
    }

    void put(std::size_t i, const Entry& e) {
        heap_[i] = e;
        pos_[e.t] = static_cast<std::uint32_t>(i + 1);
    }

    std::size_t sift_up(std::size_t i) {
        const Entry e = heap_[i];
        while (i > 0) {
            const std::size_t parent = (i - 1) / 2;
            if (!first(e, heap_[parent])) {
                break;
            }
            put(i, heap_[parent]);
            i = parent;
        }
        put(i, e);
        return i;
    }

    void sift_down(std::size_t i) {
        const Entry e = heap_[i];
        const std::size_t n = heap_.size();
        for (;;) {
            std::size_t child = 2 * i + 1;
            if (child >= n) {
                break;
            }
            if (child + 1 < n && first(heap_[child + 1], heap_[child])) {
                ++child;
            }
            if (!first(heap_[child], e)) {
                break;
            }
            put(i, heap_[child]);
            i = child;
        }
        put(i, e);
    }

    LargeVector<Entry> heap_;
    LargeVector<std::uint32_t> pos_; // triangle -> its heap slot + 1; 0 when absent
};

} // namespace tb::core
