// Lu & Yun §3.3 "Split": the split agent (perfectionist). The triangle with the most error
// points is split at its worst sample (a sample on an edge splits the edge and its neighbour,
// figure 4c), then diagonals are swapped toward fewer error points, Delaunay on ties, and the
// swaps propagate recursively inside the fan of the new point (figure 4b). A swap is made only
// across a strictly convex quadrilateral, so no triangle ever loses its positive area.
#include "core/error.hpp"
#include "core/predicates.hpp"
#include "core/refiner.hpp"

namespace tb::core {

Refiner::Refiner(const HeightGrid& grid, double eps, bool lock_border, Tin tin)
    : grid_(grid), eps_(eps), lock_border_(lock_border), tin_(std::move(tin)) {
    for (Index t = 0; t < tin_.triangle_slots(); ++t) {
        if (tin_.alive(t)) {
            set_stats(t, scan(t));
        }
    }
}

void Refiner::compact() {
    const std::vector<Index> old_of = tin_.compact();
    std::vector<TriangleStats> stats(old_of.size());
    for (Index t = 0; t < old_of.size(); ++t) {
        stats[t] = stats_[old_of[t]];
    }
    stats_ = std::move(stats);
    version_.assign(stats_.size(), 0);
    dirty_.assign(tin_.points.size(), 1);
    queue_ = {};
    for (Index t = 0; t < stats_.size(); ++t) {
        const TriangleStats& st = stats_[t];
        if (st.error_points > 0) {
            const double fraction = static_cast<double>(st.error_points) / st.samples;
            queue_.push({st.error_points, fraction, st.total_error, t, version_[t]});
        }
    }
}

TriangleStats Refiner::scan(Index a, Index b, Index c, std::int64_t stop_at) const {
    return scan_triangle(grid_, eps_, tin_.points[a], tin_.points[b], tin_.points[c], stop_at);
}

TriangleStats Refiner::scan(Index t) const {
    return scan(tin_.triangles[3 * t], tin_.triangles[3 * t + 1], tin_.triangles[3 * t + 2]);
}

void Refiner::set_stats(Index t, const TriangleStats& st) {
    if (stats_.size() <= t) {
        stats_.resize(tin_.triangle_slots());
        version_.resize(tin_.triangle_slots(), 0);
    }
    error_points_ += st.error_points - stats_[t].error_points;
    stats_[t] = st;
    ++version_[t];
    if (dirty_.size() < tin_.points.size()) {
        dirty_.resize(tin_.points.size() + tin_.points.size() / 2, 1);
    }
    if (tin_.alive(t)) {
        for (Index e = 3 * t; e < 3 * t + 3; ++e) {
            dirty_[tin_.triangles[e]] = 1;
        }
    }
    if (st.error_points > 0) {
        const double fraction = static_cast<double>(st.error_points) / st.samples;
        queue_.push({st.error_points, fraction, st.total_error, t, version_[t]});
    }
}

void Refiner::release(Index t) {
    set_stats(t, TriangleStats{});
    tin_.free_triangle(t);
}

void Refiner::swap_around(Index p, std::vector<Index>& stack) {
    while (!stack.empty()) {
        const Index e = stack.back();
        stack.pop_back();
        const Index f = tin_.halfedges[e];
        if (f == kNone) {
            continue;
        }
        // e = a -> b opposite p in (a, b, p); the twin's triangle has the far vertex d.
        const Index a = tin_.triangles[e];
        const Index b = tin_.triangles[next_edge(e)];
        TB_ASSERT(tin_.triangles[prev_edge(e)] == p);
        const Index d = tin_.triangles[prev_edge(f)];
        const GridPoint pa = tin_.points[a], pb = tin_.points[b];
        const GridPoint pp = tin_.points[p], pd = tin_.points[d];
        if (orient2d(pp, pa, pd) <= 0 || orient2d(pd, pb, pp) <= 0) {
            continue; // not strictly convex: the swap would fold a triangle
        }
        const Index t = e / 3, u = f / 3;
        // Swap when the other diagonal leaves fewer error points, or as many and Delaunay
        // prefers it: so the new pair may have at most `limit` error points. Scans stop as soon
        // as the limit is passed (a winning swap's scans are complete), and a pair that is clean
        // and Delaunay already is not scanned at all.
        const std::int64_t now = std::int64_t{stats_[t].error_points} + stats_[u].error_points;
        const std::int64_t limit = incircle(pa, pb, pp, pd) > 0 ? now : now - 1;
        if (limit < 0) {
            continue;
        }
        const TriangleStats left = scan(p, a, d, limit + 1);
        if (left.error_points > limit) {
            continue;
        }
        const TriangleStats right = scan(d, b, p, limit - left.error_points + 1);
        if (left.error_points + right.error_points > limit) {
            continue;
        }
        [[maybe_unused]] const Index dp = tin_.flip(e); // t = (p, a, d), u = (d, b, p)
        TB_ASSERT(dp / 3 == t && tin_.halfedges[dp] / 3 == u);
        set_stats(t, left);
        set_stats(u, right);
        stack.push_back(3 * t + 1); // a -> d
        stack.push_back(3 * u);     // d -> b
    }
}

void Refiner::split_until_clean() {
    std::vector<Index> stack;
    std::array<Index, 4> around{};
    while (!queue_.empty()) {
        const QueueEntry top = queue_.top();
        queue_.pop();
        const Index t = top.t;
        if (top.version != version_[t] || !tin_.alive(t) || stats_[t].error_points == 0) {
            continue;
        }
        const std::int64_t s = stats_[t].worst_sample;
        TB_ASSERT(s >= 0);
        const GridPoint q{static_cast<std::int32_t>(s % grid_.width),
                          static_cast<std::int32_t>(s / grid_.width)};
        Index on_edge = kNone;
        for (Index e = 3 * t; e < 3 * t + 3; ++e) {
            if (orient2d(tin_.start(e), tin_.points[tin_.triangles[next_edge(e)]], q) == 0) {
                on_edge = e;
            }
        }
        const Index p = tin_.add_point(q);
        int count = 3;
        if (on_edge == kNone) {
            tin_.split_triangle(t, p, around);
        } else {
            // A locked border is the exact 1-D fit: its samples are never error points.
            TB_ASSERT(!lock_border_ || tin_.halfedges[on_edge] != kNone);
            count = tin_.split_edge(on_edge, p, around);
        }
        stack.clear();
        for (int i = 0; i < count; ++i) {
            const Index tt = around[static_cast<std::size_t>(i)];
            set_stats(tt, scan(tt));
            for (Index e = 3 * tt; e < 3 * tt + 3; ++e) {
                if (tin_.triangles[e] != p && tin_.triangles[next_edge(e)] != p) {
                    stack.push_back(e);
                }
            }
        }
        swap_around(p, stack);
    }
    TB_ASSERT(error_points_ == 0);
}

} // namespace tb::core
