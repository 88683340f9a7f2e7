// Lu & Yun §3.1: "The 2D Delaunay triangulation using all the above computed break points is
// computed in the x-y image plane." Incremental insertion with Lawson flips, exact integers.
#include "core/delaunay.hpp"

#include <algorithm>

#include "core/error.hpp"
#include "core/predicates.hpp"

namespace tb::core {

Location locate(const Tin& tin, GridPoint p, Index start) {
    Index t = start;
    for (std::size_t steps = 0;; ++steps) {
        TB_ASSERT(steps <= 4 * tin.triangle_slots() + 8);
        Index zero_edge = kNone;
        int zeros = 0;
        bool moved = false;
        // Start the edge test at a rotating offset so the walk cannot bounce between two
        // triangles on a cocircular grid.
        for (Index k = 0; k < 3; ++k) {
            const Index e = 3 * t + (k + static_cast<Index>(steps)) % 3;
            const std::int64_t o =
                orient2d(tin.start(e), tin.points[tin.triangles[next_edge(e)]], p);
            if (o < 0) {
                TB_ASSERT(tin.halfedges[e] != kNone);
                t = tin.halfedges[e] / 3;
                moved = true;
                break;
            }
            if (o == 0) {
                ++zeros;
                zero_edge = e;
            }
        }
        if (moved) {
            continue;
        }
        if (zeros == 0) {
            return {Location::kInside, t};
        }
        if (zeros == 1) {
            return {Location::kOnEdge, zero_edge};
        }
        for (Index e = 3 * t; e < 3 * t + 3; ++e) {
            if (tin.start(e) == p) {
                return {Location::kVertex, tin.triangles[e]};
            }
        }
        TB_ASSERT(false);
    }
}

namespace {

// Restores the empty-circle property around the new vertex p after an insertion (Lawson).
void legalize(Tin& tin, Index p, std::vector<Index>& stack) {
    while (!stack.empty()) {
        const Index e = stack.back();
        stack.pop_back();
        const Index f = tin.halfedges[e];
        if (f == kNone) {
            continue;
        }
        // e = a -> b opposite p in triangle (a, b, p); f's triangle has the far vertex d.
        const GridPoint a = tin.start(e);
        const GridPoint b = tin.points[tin.triangles[next_edge(e)]];
        [[maybe_unused]] const Index pv = tin.triangles[prev_edge(e)];
        TB_ASSERT(pv == p);
        const GridPoint d = tin.points[tin.triangles[prev_edge(f)]];
        if (incircle(a, b, tin.points[p], d) <= 0) {
            continue;
        }
        const Index sr = tin.flip(e);
        // After the flip: (p, a, d) and (d, b, p); the edges opposite p are a -> d and d -> b.
        const Index t = sr / 3;
        const Index u = tin.halfedges[sr] / 3;
        stack.push_back(3 * t + 1);
        stack.push_back(3 * u);
    }
}

} // namespace

Tin delaunay_rectangle(int width,
                       int height,
                       const std::vector<GridPoint>& points,
                       std::size_t room) {
    Tin tin = Tin::rectangle(width, height);
    tin.reserve(std::max(room, points.size() + 4));
    std::vector<Index> stack;
    std::array<Index, 4> around{};
    Index last = 0;
    for (const GridPoint& q : points) {
        TB_ASSERT(q.x >= 0 && q.y >= 0 && q.x < width && q.y < height);
        const Location loc = locate(tin, q, last);
        if (loc.kind == Location::kVertex) {
            continue;
        }
        const Index p = tin.add_point(q);
        int count = 3;
        if (loc.kind == Location::kInside) {
            tin.split_triangle(loc.where, p, around);
        } else {
            count = tin.split_edge(loc.where, p, around);
        }
        stack.clear();
        for (int i = 0; i < count; ++i) {
            // The edge opposite p in each triangle around p.
            const Index t = around[static_cast<std::size_t>(i)];
            for (Index e = 3 * t; e < 3 * t + 3; ++e) {
                if (tin.triangles[e] != p && tin.triangles[next_edge(e)] != p) {
                    stack.push_back(e);
                }
            }
        }
        legalize(tin, p, stack);
        last = tin.vertex_edge[p] / 3;
    }
    return tin;
}

} // namespace tb::core
