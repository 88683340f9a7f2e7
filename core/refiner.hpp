#pragma once
// Lu & Yun §3.3-3.4: the split agent and the merge agent working on one triangulation. The
// class guards the invariant that stats_[t] is the error scan of every live triangle t and that
// every live triangle with error points has a current entry in the split queue.
#include <cstdint>
#include <queue>
#include <vector>

#include "core/error_scan.hpp"
#include "core/polygon_dp.hpp"
#include "core/tin.hpp"
#include "core/triangulate.hpp"

namespace tb::core {

class Refiner {
public:
    // Takes the initial triangulation (§3.1) and scans every triangle. grid must outlive the
    // refiner (it is kept by reference); eps > 0.
    Refiner(const HeightGrid& grid, double eps, bool lock_border, Tin tin);

    // The split agent (split.cpp): while some valid sample is over eps, insert the worst sample
    // of the triangle with the most error points and swap diagonals around it. On return
    // error_points() == 0.
    void split_until_clean();

    // One pass of the merge agent (merge.cpp) over the vertices, flattest neighbourhood first:
    // a vertex is removed when the optimal re-triangulation of its hole has no more error points
    // than its neighbourhood had. Vertices already tried whose neighbourhood has not changed
    // since are skipped. Returns the number of vertices removed.
    std::size_t merge_pass();

    // Renumbers vertices and triangles along a Z-order curve (Tin::compact) so that the merge
    // agent's walks stay in cache; caches and queue follow. Vertex indices change.
    void compact();

    std::int64_t error_points() const { return error_points_; }
    const Tin& tin() const { return tin_; }

private:
    struct QueueEntry {
        std::int64_t error_points;
        double fraction;
        double total_error;
        Index t;
        std::uint32_t version;
        // Most error points first, then error-point fraction, total error, lower index.
        friend bool operator<(const QueueEntry& a, const QueueEntry& b) {
            if (a.error_points != b.error_points) {
                return a.error_points < b.error_points;
            }
            if (a.fraction != b.fraction) {
                return a.fraction < b.fraction;
            }
            if (a.total_error != b.total_error) {
                return a.total_error < b.total_error;
            }
            return a.t > b.t;
        }
    };

    TriangleStats scan(Index a, Index b, Index c, std::int64_t stop_at = INT64_MAX) const;
    TriangleStats scan(Index t) const;
    void set_stats(Index t, const TriangleStats& st); // also (re)queues t
    void release(Index t);                            // forgets t's stats, frees it
    void swap_around(Index p, std::vector<Index>& stack);
    bool try_remove(Index v, std::vector<Index>& ring);

    const HeightGrid& grid_;
    double eps_;
    bool lock_border_;
    Tin tin_;
    std::vector<TriangleStats> stats_;
    std::vector<std::uint32_t> version_;
    std::priority_queue<QueueEntry> queue_;
    std::int64_t error_points_ = 0;
    // Vertex v's neighbourhood changed since the merge agent last failed to remove it.
    std::vector<std::uint8_t> dirty_;
    // Working memory of try_remove, kept to save allocations.
    struct MergeScratch {
        std::vector<Index> poly;
        std::vector<GridPoint> pts;
        std::vector<std::uint8_t> state;
        std::vector<TriangleCost> estimate;
        std::vector<std::pair<std::size_t, TriangleStats>> exact;
        std::vector<std::int8_t> side;
        PolygonDpScratch dp;
    } scratch_;
};

} // namespace tb::core
