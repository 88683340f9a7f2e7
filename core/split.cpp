// Lu & Yun §3.3 "Split": the split agent (perfectionist). The triangle with the most error
// points is split at its worst sample (a sample on an edge splits the edge and its neighbour,
// figure 4c), then diagonals are swapped toward fewer error points, Delaunay on ties, and the
// swaps propagate recursively inside the fan of the new point (figure 4b). A swap is made only
// across a strictly convex quadrilateral, so no triangle ever loses its positive area.
//
// The edge bound (TriangulateOptions::max_edge) is an addition to the paper: swaps never make
// an edge over max_edge, and once no sample is over eps the globally longest over-long edge is
// removed: split at the lattice sample nearest its midpoint, else (its two triangles hold no
// other sample) swapped. Each step either inserts a vertex (finitely many samples) or replaces
// the longest edge by a strictly shorter one, so the loop ends.
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <numeric>

#include "core/error.hpp"
#include "core/predicates.hpp"
#include "core/refiner.hpp"
#include "core/two_threads.hpp"

namespace tb::core {

namespace {

std::int64_t length2(GridPoint a, GridPoint b) {
    const std::int64_t dx = b.x - a.x, dy = b.y - a.y;
    return dx * dx + dy * dy;
}

// The largest integer k with sqrt(k) <= max_edge, as the final check computes lengths.
std::int64_t max_length2(double max_edge) {
    if (!(max_edge > 0.0) || max_edge >= 4.0e6) {
        return INT64_MAX; // no limit, or longer than any grid diagonal (2^20 * sqrt(2))
    }
    auto k = static_cast<std::int64_t>(std::floor(max_edge * max_edge));
    while (std::sqrt(static_cast<double>(k + 1)) <= max_edge) {
        ++k;
    }
    while (k > 0 && std::sqrt(static_cast<double>(k)) > max_edge) {
        --k;
    }
    return k;
}

} // namespace

Refiner::Refiner(
    const HeightGrid& grid, double eps, bool lock_border, double max_edge, Tin tin, int threads)
    : grid_(grid), eps_(eps), lock_border_(lock_border), max_edge_(max_edge),
      max_edge2_floor_(max_length2(max_edge)), tin_(std::move(tin)) {
    // The split agent adds vertices to the start's anchors: room for kGrowth times as many, so
    // that the arrays do not move as they grow (for the triangulation's own a no-op when the
    // start was built with that room, as triangulate() does).
    const std::size_t room = kGrowth * tin_.points.size();
    tin_.reserve(room);
    stats_.reserve(2 * room);
    dirty_.reserve(room + room / 2); // set_stats grows it by half at a time
    queue_.reserve(2 * room);
    // The scans read the grid and the tin only: two halves of the slots at once on a big grid,
    // then their stats in slot order.
    const Index slots = static_cast<Index>(tin_.triangle_slots());
    const bool two = threads >= 2 &&
                     static_cast<std::size_t>(grid.width) * static_cast<std::size_t>(grid.height) >=
                         kTwoThreadSamples;
    std::vector<TriangleStats> scanned(slots);
    const auto scan_slots = [&](Index from, Index to) {
        for (Index t = from; t < to; ++t) {
            if (tin_.alive(t)) {
                scanned[t] = scan(t);
            }
        }
    };
    run_both(
        two, [&] { scan_slots(0, slots / 2); }, [&] { scan_slots(slots / 2, slots); });
    for (Index t = 0; t < slots; ++t) {
        if (tin_.alive(t)) {
            set_stats(t, scanned[t]);
        }
    }
}

void Refiner::compact() {
    // Every slot has stats (a freed one empty ones); they move with their triangles.
    stats_.resize(tin_.triangle_slots());
    tin_.compact([this](Index a, Index b) { std::swap(stats_[a], stats_[b]); });
    stats_.resize(tin_.triangle_slots());
    dirty_.assign(tin_.points.size(), 1);
    queue_.clear();
    long_queue_ = {};
    for (Index t = 0; t < stats_.size(); ++t) {
        Index e = kNone;
        const std::int64_t l2 = longest_edge2(t, e);
        if (l2 > max_edge2_floor_) {
            long_queue_.push({l2, -static_cast<std::int64_t>(t)});
        }
        const TriangleStats& st = stats_[t];
        if (st.error_points > 0) {
            const double fraction = static_cast<double>(st.error_points) / st.samples;
            queue_.set(t, st.error_points, fraction, st.total_error);
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
    }
    if (st.error_points != stats_[t].error_points) {
        // Not written when both are 0: the merge agent's two workers set stats at once.
        error_points_ += st.error_points - stats_[t].error_points;
    }
    stats_[t] = st;
    if (dirty_.size() < tin_.points.size()) {
        dirty_.resize(tin_.points.size() + tin_.points.size() / 2, 1);
    }
    if (tin_.alive(t)) {
        for (Index e = 3 * t; e < 3 * t + 3; ++e) {
            dirty_[tin_.triangles[e]] = 1;
        }
        if (max_edge2_floor_ != INT64_MAX) {
            Index e = kNone;
            const std::int64_t l2 = longest_edge2(t, e);
            if (l2 > max_edge2_floor_) {
                long_queue_.push({l2, -static_cast<std::int64_t>(t)});
            }
        }
    }
    if (st.error_points > 0) {
        const double fraction = static_cast<double>(st.error_points) / st.samples;
        queue_.set(t, st.error_points, fraction, st.total_error);
    } else {
        queue_.erase(t);
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
        if (limit < 0 || too_long(pp, pd)) {
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

std::int64_t Refiner::longest_edge2(Index t, Index& edge) const {
    const GridPoint a = tin_.points[tin_.triangles[3 * t]];
    const GridPoint b = tin_.points[tin_.triangles[3 * t + 1]];
    const GridPoint c = tin_.points[tin_.triangles[3 * t + 2]];
    const std::int64_t ab = length2(a, b), bc = length2(b, c), ca = length2(c, a);
    // The first of equals, in half-edge order a -> b, b -> c, c -> a.
    if (ab >= bc && ab >= ca) {
        edge = 3 * t;
        return ab;
    }
    if (bc >= ca) {
        edge = 3 * t + 1;
        return bc;
    }
    edge = 3 * t + 2;
    return ca;
}

void Refiner::insert_at(Index t, GridPoint q, std::vector<Index>& stack) {
    // q lies in the closed triangle t and is no vertex: split t, or the edge q lies on.
    std::array<Index, 4> around{};
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
        // A locked border is the exact 1-D fit: its samples are never error points, and the
        // edge-shortening pass skips them.
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

void Refiner::shorten(Index e, std::vector<Index>& stack) {
    // e = a -> b is the longest edge of the mesh, over max_edge; t = (a, b, c) and, across e,
    // u = (b, a, d). Every edge of t and u is at most |ab|.
    const Index f = tin_.halfedges[e];
    const GridPoint a = tin_.start(e), b = tin_.points[tin_.triangles[next_edge(e)]];
    const GridPoint c = tin_.points[tin_.triangles[prev_edge(e)]];
    // A locked border is the 1-D fit with steps of at most floor(max_edge): never over-long.
    TB_ASSERT(f != kNone || !lock_border_);
    const std::int64_t dx = b.x - a.x, dy = b.y - a.y;
    const std::int64_t g = std::gcd(std::abs(dx), std::abs(dy));
    if (g >= 2) {
        // Lattice samples on ab: the one nearest the midpoint, strictly inside the span (an
        // open edge of a triangulation holds no vertex).
        const std::int64_t k = g / 2;
        const GridPoint q{static_cast<std::int32_t>(a.x + dx / g * k),
                          static_cast<std::int32_t>(a.y + dy / g * k)};
        insert_at(e / 3, q, stack);
        return;
    }
    // ab holds no sample: take the sample of the closed triangles t and u nearest the
    // midpoint (doubled coordinates, exact; ties in raster order), other than their vertices.
    // Samples on a locked border edge stay out (the border must stay the 1-D fit).
    const GridPoint d = f != kNone ? tin_.points[tin_.triangles[prev_edge(f)]] : c;
    const Index tris[2] = {e / 3, f != kNone ? f / 3 : kNone};
    Index best_t = kNone;
    GridPoint best{};
    std::int64_t best_d2 = INT64_MAX;
    for (Index t : tris) {
        if (t == kNone) {
            continue;
        }
        const GridPoint p0 = tin_.points[tin_.triangles[3 * t]];
        const GridPoint p1 = tin_.points[tin_.triangles[3 * t + 1]];
        const GridPoint p2 = tin_.points[tin_.triangles[3 * t + 2]];
        const std::int32_t x0 = std::min({p0.x, p1.x, p2.x}), x1 = std::max({p0.x, p1.x, p2.x});
        const std::int32_t y0 = std::min({p0.y, p1.y, p2.y}), y1 = std::max({p0.y, p1.y, p2.y});
        for (std::int32_t y = y0; y <= y1; ++y) {
            for (std::int32_t x = x0; x <= x1; ++x) {
                const GridPoint q{x, y};
                const std::int64_t w0 = orient2d(p1, p2, q), w1 = orient2d(p2, p0, q),
                                   w2 = orient2d(p0, p1, q);
                if (w0 < 0 || w1 < 0 || w2 < 0) {
                    continue;
                }
                if ((q.x == p0.x && q.y == p0.y) || (q.x == p1.x && q.y == p1.y) ||
                    (q.x == p2.x && q.y == p2.y)) {
                    continue;
                }
                if (lock_border_) {
                    // On an edge of t without a twin: a border edge.
                    const std::int64_t w[3] = {w2, w0, w1}; // edge 3t+k runs p_k -> p_k+1
                    bool on_border = false;
                    for (Index k = 0; k < 3; ++k) {
                        if (w[k] == 0 && tin_.halfedges[3 * t + k] == kNone) {
                            on_border = true;
                        }
                    }
                    if (on_border) {
                        continue;
                    }
                }
                const std::int64_t mx = 2 * std::int64_t{x} - a.x - b.x;
                const std::int64_t my = 2 * std::int64_t{y} - a.y - b.y;
                const std::int64_t d2 = mx * mx + my * my;
                if (d2 < best_d2 || (d2 == best_d2 && raster_less(q, best))) {
                    best_d2 = d2;
                    best = q;
                    best_t = t;
                }
            }
        }
    }
    if (best_t != kNone) {
        insert_at(best_t, best, stack);
        return;
    }
    // t and u hold no other sample and ab is the longest edge of both: the quadrilateral
    // a d b c is then strictly convex and |cd| < |ab| (both triangles have doubled area 1, so
    // c = a + w + i v, d = a - w + j v with v = b - a, det(v, w) = 1, and |ac|, |bc|, |ad|,
    // |bd| <= |ab| force i + j = 1, hence |cd|^2 < |v|^2 + 4 / |v|^2 and |cd| != |v|).
    if (f == kNone || orient2d(c, a, d) <= 0 || orient2d(d, b, c) <= 0 ||
        length2(c, d) >= length2(a, b)) {
        throw Error("triangulate: internal error: cannot shorten the edge from x=" +
                    std::to_string(a.x) + " y=" + std::to_string(a.y) +
                    " to x=" + std::to_string(b.x) + " y=" + std::to_string(b.y));
    }
    const Index t = e / 3, u = f / 3;
    // flip(e): t = (c, a, d), u = (d, b, c).
    const TriangleStats left =
        scan(tin_.triangles[prev_edge(e)], tin_.triangles[e], tin_.triangles[prev_edge(f)]);
    const TriangleStats right = scan(
        tin_.triangles[prev_edge(f)], tin_.triangles[next_edge(e)], tin_.triangles[prev_edge(e)]);
    tin_.flip(e);
    set_stats(t, left);
    set_stats(u, right);
}

void Refiner::split_until_clean() {
    std::vector<Index> stack;
    for (;;) {
        if (queue_.empty()) {
            // Clean: remove the longest over-long edge, if any, then go on splitting.
            if (long_queue_.empty()) {
                break;
            }
            const auto [l2, minus_t] = long_queue_.top();
            long_queue_.pop();
            const auto t = static_cast<Index>(-minus_t);
            if (t >= tin_.triangle_slots() || !tin_.alive(t)) {
                continue;
            }
            Index e = kNone;
            if (longest_edge2(t, e) != l2) {
                continue; // stale: t changed and was pushed again
            }
            shorten(e, stack);
            continue;
        }
        const Index t = queue_.top();
        TB_ASSERT(tin_.alive(t) && stats_[t].error_points > 0);
        const std::int64_t s = stats_[t].worst_sample;
        TB_ASSERT(s >= 0);
        const GridPoint q{static_cast<std::int32_t>(s % grid_.width),
                          static_cast<std::int32_t>(s / grid_.width)};
        insert_at(t, q, stack);
    }
    TB_ASSERT(error_points_ == 0);
}

} // namespace tb::core
