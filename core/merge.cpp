// Lu & Yun §3.4 "Merge": the merge agent (economist). A vertex is removed and its hole
// re-triangulated optimally (polygon_dp.cpp) when that does not increase the neighbourhood's
// error points. Border vertices are removed only when the border is not locked, only along a
// straight border, and never at the four corners. Triangles with an edge over max_edge are
// never used, so a vertex whose hole has no such re-triangulation stays.
//
// The paper visits the vertices flattest neighbourhood first. Here they are visited along a
// Z-order curve of their positions, neighbourhoods with fewer error points first when there
// are any: measured on bench/mesh_bench.sh's cases, the flatness order (by octaves of the
// largest deviation of an incident normal from the mean normal) ended with 0.5-1.8% more
// triangles than the spatial order, and merged 4-16% slower, since each visit jumped across
// the mesh where the spatial order finds the neighbourhood still in cache. Either way each
// removal is decided by the same exact test.
//
// On a big grid a pass works the halves left and right of the middle column apart, on two
// threads (merge_pass): a removal changes only the triangles around the removed vertex, so
// two vertices whose neighbourhoods lie on opposite sides never see each other's work, and
// the mesh does not depend on which half runs first.
#include <algorithm>
#include <array>
#include <cmath>

#include "core/error.hpp"
#include "core/memory.hpp"
#include "core/polygon_dp.hpp"
#include "core/predicates.hpp"
#include "core/refiner.hpp"
#include "core/two_threads.hpp"

namespace tb::core {
namespace {

// Candidate triangles are estimated on every kStride-th row and column, except those smaller
// than kSmallTriangle (doubled area), which are scanned in full at once.
constexpr int kStride = 2;
constexpr std::int64_t kSmallTriangle = 64;

// Visit order: fewer error points in the neighbourhood (41 bits; only a merge before the split
// is clean has any), then position along the Z-order curve, unique per vertex.
struct Candidate {
    std::uint64_t error_points;
    std::uint64_t z_order;
    Index v;
    friend bool operator<(const Candidate& a, const Candidate& b) {
        return a.error_points != b.error_points ? a.error_points < b.error_points
                                                : a.z_order < b.z_order;
    }
};

} // namespace

bool Refiner::try_remove(Index v, MergeWorker& w, const MergeLimits& limits) {
    std::vector<Index>& ring = w.ring;
    tin_.ring(v, ring);
    const bool border = tin_.halfedges[ring.front()] == kNone;
    auto& poly = w.poly;
    auto& pts = w.pts;
    poly.clear();
    pts.clear();
    std::int64_t before = 0;
    for (Index e : ring) {
        poly.push_back(tin_.triangles[next_edge(e)]);
        if (error_points_ != 0) {
            before += stats_[e / 3].error_points;
        }
    }
    if (border) {
        // The last neighbour, reached over the last triangle's far edge.
        poly.push_back(tin_.triangles[prev_edge(ring.back())]);
    }
    if (poly.size() > limits.max_hole || poly.size() < 3) {
        return false;
    }
    for (Index u : poly) {
        pts.push_back(tin_.points[u]);
    }
    if (border && orient2d(pts.back(), tin_.points[v], pts.front()) != 0) {
        return false; // a corner
    }
    const std::size_t n = poly.size();
    // The removed vertex is itself a sample the new triangles must honour (when the
    // neighbourhood is clean, as after a full split). Its height must lie within eps of the
    // hole's height range, since interpolation never leaves it.
    const GridPoint pv = tin_.points[v];
    const bool v_counts = before == 0 && grid_.is_valid(pv.x, pv.y);
    const double zv = grid_.at(pv.x, pv.y);
    if (v_counts) {
        double lo = grid_.at(pts[0].x, pts[0].y), hi = lo;
        for (const GridPoint& q : pts) {
            lo = std::min(lo, static_cast<double>(grid_.at(q.x, q.y)));
            hi = std::max(hi, static_cast<double>(grid_.at(q.x, q.y)));
        }
        if (zv - hi > eps_ || lo - zv > eps_) {
            return false;
        }
    }
    // orient2d(pts[i], pts[j], pv) for i < j: the weights of v in every candidate triangle,
    // computed once per pair instead of three times per triangle.
    auto& toward_v = w.toward_v;
    if (v_counts) {
        toward_v.resize(n * n);
        for (std::size_t i = 0; i < n; ++i) {
            for (std::size_t j = i + 1; j < n; ++j) {
                toward_v[i * n + j] = orient2d(pts[i], pts[j], pv);
            }
        }
    }
    const auto at = [&](int r, int q) {
        return toward_v[static_cast<std::size_t>(r) * n + static_cast<std::size_t>(q)];
    };
    // Whether a candidate triangle (i < j < k) honours v, if it covers v: an O(1) test before
    // any scan.
    const auto honours_v = [&](int i, int j, int k, bool& covers) {
        const GridPoint a = pts[static_cast<std::size_t>(i)];
        const GridPoint b = pts[static_cast<std::size_t>(j)];
        const GridPoint c = pts[static_cast<std::size_t>(k)];
        // orient2d(b, c, pv), orient2d(c, a, pv) = -orient2d(a, c, pv), orient2d(a, b, pv).
        const std::int64_t wa = at(j, k), wb = -at(i, k), wc = at(i, j);
        // The three sum to orient2d(a, b, c) exactly, wherever pv lies.
        const std::int64_t area = wa + wb + wc;
        covers = wa >= 0 && wb >= 0 && wc >= 0 && area > 0;
        if (!covers) {
            return true;
        }
        const double z = interpolate(a,
                                     grid_.at(a.x, a.y),
                                     b,
                                     grid_.at(b.x, b.y),
                                     c,
                                     grid_.at(c.x, c.y),
                                     wa,
                                     wb,
                                     wc,
                                     1.0 / static_cast<double>(area), // inverse_area(a, b, c)
                                     pv);
        return std::abs(z - zv) <= eps_;
    };
    // The dynamic program runs on estimates: each candidate triangle is scanned on a coarse
    // lattice of samples (every kStride-th row and column; small triangles in full). Error
    // points seen there are real, so such triangles are out. The winning triangulation is then
    // scanned in full; a triangle that fails is ruled out and the program runs again. Only
    // exact full scans ever decide a removal.
    const auto key = [n](int i, int j, int k) {
        return (static_cast<std::size_t>(i) * n + static_cast<std::size_t>(j)) * n +
               static_cast<std::size_t>(k);
    };
    enum : std::uint8_t { kUnknown, kEstimated, kExact, kRuledOut };
    auto& state = w.state;
    state.assign(n * n * n, kUnknown);
    auto& estimate = w.estimate;
    // Read only where state says it was written: grow, never shrink and refill.
    if (estimate.size() < n * n * n) {
        estimate.resize(n * n * n);
    }
    auto& exact = w.exact;
    exact.clear();
    const auto cost = [&](int i, int j, int k) -> std::optional<TriangleCost> {
        const std::size_t id = key(i, j, k);
        if (state[id] == kRuledOut) {
            return std::nullopt;
        }
        if (state[id] != kUnknown) {
            return estimate[id];
        }
        if (too_long(pts[static_cast<std::size_t>(i)], pts[static_cast<std::size_t>(j)]) ||
            too_long(pts[static_cast<std::size_t>(j)], pts[static_cast<std::size_t>(k)]) ||
            too_long(pts[static_cast<std::size_t>(k)], pts[static_cast<std::size_t>(i)])) {
            // An edge over max_edge (a diagonal, or the closing edge of a border hole): the
            // triangle may not be used; with none left the vertex stays.
            state[id] = kRuledOut;
            return std::nullopt;
        }
        bool covers = false;
        if (v_counts && !honours_v(i, j, k, covers)) {
            state[id] = kRuledOut;
            return std::nullopt;
        }
        const Index a = poly[static_cast<std::size_t>(i)], b = poly[static_cast<std::size_t>(j)],
                    c = poly[static_cast<std::size_t>(k)];
        const std::int64_t area = orient2d(tin_.points[a], tin_.points[b], tin_.points[c]);
        const int stride = area < kSmallTriangle ? 1 : kStride;
        const TriangleStats st = scan_triangle(
            grid_, eps_, tin_.points[a], tin_.points[b], tin_.points[c], before + 1, stride);
        if (st.error_points > before) {
            state[id] = kRuledOut;
            return std::nullopt;
        }
        state[id] = stride == 1 ? kExact : kEstimated;
        estimate[id] = TriangleCost{st.error_points, st.total_error * stride * stride};
        if (stride == 1) {
            exact.push_back({id, st});
        }
        return estimate[id];
    };
    // Every re-triangulation has a triangle covering v. Those candidates are tried first, so
    // that a removal that cannot work usually fails after a few scans instead of all of them.
    // The sides found valid or not here are the dynamic program's too (the same test).
    auto& dp = w.dp;
    dp.side.assign(n * n, -1);
    if (v_counts) {
        const auto side_ok = [&](int i, int k) { return dp.side_ok(pts, &pv, i, k); };
        // In the same order as every (i < j < k), but the signs of toward_v rule out most of
        // the triangles not covering v before honours_v looks at them: (i, j, k) covers v only
        // when orient2d(pts[i], pts[j], pv) >= 0, orient2d(pts[j], pts[k], pv) >= 0 and
        // orient2d(pts[i], pts[k], pv) <= 0.
        bool any = false;
        for (int i = 0; i < static_cast<int>(n) && !any; ++i) {
            for (int j = i + 1; j < static_cast<int>(n) && !any; ++j) {
                if (at(i, j) < 0) {
                    continue;
                }
                for (int k = j + 1; k < static_cast<int>(n) && !any; ++k) {
                    if (at(j, k) < 0 || at(i, k) > 0) {
                        continue;
                    }
                    bool covers = false;
                    if (honours_v(i, j, k, covers) && covers && side_ok(i, j) && side_ok(j, k) &&
                        side_ok(i, k)) {
                        any = cost(i, j, k).has_value();
                    }
                }
            }
        }
        if (!any) {
            return false;
        }
    }
    std::optional<std::vector<std::array<int, 3>>> tris;
    for (int attempt = 0;; ++attempt) {
        if (attempt == limits.max_attempts) {
            return false;
        }
        dp.side_ready = true; // this polygon's sides, as far as known
        tris = triangulate_polygon(pts, cost, nullptr, &dp, &pv);
        if (!tris) {
            return false;
        }
        bool verified = true;
        std::int64_t total = 0;
        for (const auto& [i, j, k] : *tris) {
            const std::size_t id = key(i, j, k);
            if (state[id] == kEstimated) {
                const TriangleStats st = scan(poly[static_cast<std::size_t>(i)],
                                              poly[static_cast<std::size_t>(j)],
                                              poly[static_cast<std::size_t>(k)],
                                              before + 1);
                if (st.error_points > before) {
                    state[id] = kRuledOut;
                    verified = false;
                    continue;
                }
                state[id] = kExact;
                exact.push_back({id, st});
            }
            const auto it = std::find_if(
                exact.begin(), exact.end(), [&](const auto& m) { return m.first == id; });
            total += it->second.error_points;
        }
        if (!verified) {
            continue;
        }
        if (total > before) {
            return false;
        }
        break;
    }
    // Outer twins of the hole's edges: poly[k] -> poly[k + 1] is the far edge of ring[k].
    auto& outer = w.outer;
    outer.assign(n, kNone);
    for (std::size_t k = 0; k < ring.size(); ++k) {
        outer[k] = tin_.halfedges[next_edge(ring[k])];
    }
    for (Index e : ring) {
        release(e / 3, w);
    }
    tin_.vertex_edge[v] = kNone;
    // A diagonal poly[from] -> poly[to] waits in `diagonal` until its twin poly[to] -> poly[from]
    // comes with a later triangle.
    auto& diagonal = w.diagonal;
    diagonal.assign(n * n, kNone);
    for (const auto& [i, j, k] : *tris) {
        const Index t = add_triangle(poly[static_cast<std::size_t>(i)],
                                     poly[static_cast<std::size_t>(j)],
                                     poly[static_cast<std::size_t>(k)],
                                     w);
        const std::array<int, 3> corner{i, j, k};
        for (int s = 0; s < 3; ++s) {
            const auto from = static_cast<std::size_t>(corner[static_cast<std::size_t>(s)]);
            const auto to = static_cast<std::size_t>(corner[static_cast<std::size_t>((s + 1) % 3)]);
            const Index e = 3 * t + static_cast<Index>(s);
            if ((from + 1) % n == to) {
                tin_.link(e, outer[from]);
            } else if (diagonal[to * n + from] != kNone) {
                tin_.link(e, diagonal[to * n + from]);
            } else {
                diagonal[from * n + to] = e;
            }
        }
        const std::size_t id = key(i, j, k);
        const auto it =
            std::find_if(exact.begin(), exact.end(), [&](const auto& m) { return m.first == id; });
        TB_ASSERT(it != exact.end());
        set_stats(t, it->second);
    }
    return true;
}

void Refiner::release(Index t, MergeWorker& w) {
    if (!w.local) {
        release(t);
        return;
    }
    set_stats(t, TriangleStats{});
    tin_.clear_triangle(t);
    w.slots.push_back(t);
}

Index Refiner::add_triangle(Index a, Index b, Index c, MergeWorker& w) {
    if (!w.local) {
        return tin_.add_triangle(a, b, c);
    }
    TB_ASSERT(!w.slots.empty());
    const Index t = w.slots.back();
    w.slots.pop_back();
    tin_.fill_triangle(t, a, b, c);
    return t;
}

LargeVector<Index> Refiner::merge_visit_list() {
    const std::size_t nv = tin_.points.size();
    // The error points around each vertex, when there are any.
    LargeVector<std::int64_t> error_points;
    if (error_points_ != 0) {
        error_points.assign(nv, 0);
        for (Index t = 0; t < tin_.triangle_slots(); ++t) {
            if (tin_.alive(t)) {
                for (Index e = 3 * t; e < 3 * t + 3; ++e) {
                    error_points[tin_.triangles[e]] += stats_[t].error_points;
                }
            }
        }
    }
    // Vertices tried before and untouched since (dirty_ == 0) are left out: their removal
    // would fail the same way.
    LargeVector<Index> visit;
    visit.reserve(nv);
    // After compact() the vertices are numbered along the Z-order curve, and a clean mesh's
    // merge passes add none: the list is then already in order, found so in the same pass.
    bool in_order = error_points.empty();
    std::uint64_t last_key = 0;
    for (Index v = 0; v < nv; ++v) {
        const GridPoint p = tin_.points[v];
        const bool border =
            p.x == 0 || p.y == 0 || p.x == grid_.width - 1 || p.y == grid_.height - 1;
        if (tin_.vertex_edge[v] == kNone || dirty_[v] == 0 || (lock_border_ && border)) {
            continue;
        }
        if (in_order) {
            const std::uint64_t key = z_order_key(p);
            in_order = visit.empty() || key > last_key;
            last_key = key;
        }
        visit.push_back(v);
    }
    if (!in_order) {
        LargeVector<Candidate> order;
        order.reserve(visit.size());
        for (Index v : visit) {
            const std::int64_t points = error_points.empty() ? 0 : error_points[v];
            order.push_back({static_cast<std::uint64_t>(points), z_order_key(tin_.points[v]), v});
        }
        std::sort(order.begin(), order.end());
        for (std::size_t i = 0; i < order.size(); ++i) {
            visit[i] = order[i].v;
        }
    }
    return visit;
}

void Refiner::merge_region(
    const LargeVector<Index>& visit, int side, int cut, MergeWorker& w, const MergeLimits& limits) {
    // Strictly on this side of the cut.
    const auto inside = [side, cut](GridPoint p) { return side == 0 ? p.x < cut : p.x > cut; };
    for (std::size_t i = 0; i < visit.size(); ++i) {
        const Index v = visit[i];
        if (!inside(tin_.points[v])) {
            if (side == 0 && tin_.points[v].x == cut) {
                w.deferred.push_back(i);
            }
            continue;
        }
        if (tin_.vertex_edge[v] == kNone || dirty_[v] == 0) {
            continue;
        }
        // Only this worker changes triangles whose vertices all lie on its side, and only
        // those: a neighbourhood wholly on this side is this worker's alone.
        tin_.ring(v, w.ring);
        bool mine = true;
        for (Index e : w.ring) {
            const Index t = e / 3;
            for (Index f = 3 * t; f < 3 * t + 3 && mine; ++f) {
                mine = inside(tin_.points[tin_.triangles[f]]);
            }
        }
        if (!mine) {
            w.deferred.push_back(i);
            continue;
        }
        dirty_[v] = 0;
        if (try_remove(v, w, limits)) {
            ++w.removed;
        }
    }
}

void Refiner::merge_serial(const LargeVector<Index>& visit,
                           const std::vector<std::size_t>* order,
                           MergeWorker& w,
                           const MergeLimits& limits) {
    const std::size_t n = order != nullptr ? order->size() : visit.size();
    for (std::size_t k = 0; k < n; ++k) {
        const Index v = visit[order != nullptr ? (*order)[k] : k];
        if (tin_.vertex_edge[v] == kNone || dirty_[v] == 0) {
            continue;
        }
        dirty_[v] = 0;
        if (try_remove(v, w, limits)) {
            ++w.removed;
        }
    }
}

std::size_t Refiner::merge_pass(const MergeLimits& limits) {
    dirty_.resize(tin_.points.size(), 1);
    const LargeVector<Index> visit = merge_visit_list();
    for (MergeWorker& w : workers_) {
        w.removed = 0;
        w.deferred.clear();
        w.slots.clear();
    }
    const std::size_t samples =
        static_cast<std::size_t>(grid_.width) * static_cast<std::size_t>(grid_.height);
    if (samples < kTwoThreadSamples || error_points_ != 0 || grid_.width < 8) {
        merge_serial(visit, nullptr, workers_[0], limits);
        return workers_[0].removed;
    }
    // The two halves apart. Stats, dirty flags and tin arrays are written per element, each
    // by the worker whose side it belongs to; none of them grows (a removal frees more slots
    // than it fills), and with no error points the split queue is only read.
    if (stats_.size() < tin_.triangle_slots()) {
        stats_.resize(tin_.triangle_slots());
    }
    const int cut = grid_.width / 2;
    for (int side = 0; side < 2; ++side) {
        workers_[side].local = true;
    }
    run_both(
        limits.threads >= 2,
        [&] { merge_region(visit, 0, cut, workers_[0], limits); },
        [&] { merge_region(visit, 1, cut, workers_[1], limits); });
    // Then what is left, in visit order, with the tin's free list (the workers' spare slots
    // added to it in a fixed order).
    std::vector<std::size_t> rest(workers_[0].deferred.size() + workers_[1].deferred.size());
    std::merge(workers_[0].deferred.begin(),
               workers_[0].deferred.end(),
               workers_[1].deferred.begin(),
               workers_[1].deferred.end(),
               rest.begin());
    for (MergeWorker& w : workers_) {
        tin_.free_triangles.insert(tin_.free_triangles.end(), w.slots.begin(), w.slots.end());
        w.slots.clear();
        w.local = false;
    }
    merge_serial(visit, &rest, workers_[0], limits);
    return workers_[0].removed + workers_[1].removed;
}

} // namespace tb::core
