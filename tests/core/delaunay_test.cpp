// §3.1 Delaunay start: exact, covers the rectangle, empty circles on every interior edge.
#include <doctest/doctest.h>

#include <algorithm>
#include <vector>

#include "core/delaunay.hpp"
#include "core/predicates.hpp"
#include "core/triangulate.hpp"
#include "tests/core/terrains.hpp"

namespace {

void check_delaunay(const tb::core::Tin& tin, int w, int h) {
    std::vector<float> zero(static_cast<std::size_t>(w) * h, 0.0f);
    const tb::core::Mesh m = tin.to_mesh(zero, w);
    CHECK_NOTHROW(tb::core::check_mesh(m, w, h));
    int bad = 0;
    for (std::size_t e = 0; e < m.halfedges.size(); ++e) {
        const auto twin = m.halfedges[e];
        if (twin == tb::core::kNone) {
            continue;
        }
        const auto ei = static_cast<tb::core::Index>(e);
        const auto a = m.points[m.triangles[ei]];
        const auto b = m.points[m.triangles[tb::core::next_edge(ei)]];
        const auto c = m.points[m.triangles[tb::core::prev_edge(ei)]];
        const auto d = m.points[m.triangles[tb::core::prev_edge(twin)]];
        bad += tb::core::incircle(a, b, c, d) > 0 ? 1 : 0;
    }
    CHECK(bad == 0);
}

} // namespace

TEST_CASE("the Delaunay start passes in-circle on every interior edge (seeds 1-20)") {
    for (std::uint64_t seed = 1; seed <= 20; ++seed) {
        terrain::Lcg r(seed);
        const int w = 2 + static_cast<int>(r.next() * 60), h = 2 + static_cast<int>(r.next() * 60);
        std::vector<tb::core::GridPoint> pts;
        const int n = static_cast<int>(r.next() * 200);
        for (int k = 0; k < n; ++k) {
            // Many collinear and cocircular points: snap half of them to a coarse lattice.
            int x = static_cast<int>(r.next() * w), y = static_cast<int>(r.next() * h);
            if (k % 2 == 0) {
                x -= x % 4;
                y -= y % 4;
            }
            pts.push_back({x, y});
        }
        for (int x = 0; x < w; x += 3) { // a whole border row of collinear points
            pts.push_back({x, 0});
        }
        std::sort(pts.begin(), pts.end(), tb::core::raster_less);
        pts.erase(std::unique(pts.begin(), pts.end()), pts.end());
        INFO("seed=", seed, " ", w, "x", h);
        check_delaunay(tb::core::delaunay_rectangle(w, h, pts), w, h);
    }
}

TEST_CASE("a full lattice of cocircular points triangulates without zero-area triangles") {
    std::vector<tb::core::GridPoint> pts;
    for (int y = 0; y < 9; ++y) {
        for (int x = 0; x < 11; ++x) {
            pts.push_back({x, y});
        }
    }
    const auto tin = tb::core::delaunay_rectangle(11, 9, pts);
    check_delaunay(tin, 11, 9);
    std::vector<float> zero(99, 0.0f);
    CHECK(tin.to_mesh(zero, 11).triangle_count() == 2 * 10 * 8);
}

TEST_CASE("incircle agrees with a 128-bit determinant on both sides of its int64 range") {
    // Reference: the lifted determinant in __int128 with coordinates taken relative to d,
    // written out here independently of core/predicates.hpp.
    __extension__ typedef __int128 Wide;
    const auto reference = [](tb::core::GridPoint a,
                              tb::core::GridPoint b,
                              tb::core::GridPoint c,
                              tb::core::GridPoint d) {
        const Wide ax = Wide{a.x} - d.x, ay = Wide{a.y} - d.y, bx = Wide{b.x} - d.x,
                   by = Wide{b.y} - d.y, cx = Wide{c.x} - d.x, cy = Wide{c.y} - d.y;
        const Wide det = (ax * ax + ay * ay) * (bx * cy - cx * by) -
                         (bx * bx + by * by) * (ax * cy - cx * ay) +
                         (cx * cx + cy * cy) * (ax * by - bx * ay);
        return det > 0 ? 1 : (det < 0 ? -1 : 0);
    };
    terrain::Lcg r(7);
    // Spans around 2^14, where incircle switches from int64 to __int128, up to the full grid.
    const int spans[] = {3, 200, 16383, 16384, 16385, 40000, 1 << 20};
    int checked = 0, zeros = 0;
    for (int span : spans) {
        for (int k = 0; k < 4000; ++k) {
            const auto pick = [&] {
                return tb::core::GridPoint{static_cast<std::int32_t>(r.next() * span),
                                           static_cast<std::int32_t>(r.next() * span)};
            };
            tb::core::GridPoint a = pick(), b = pick(), c = pick(), d = pick();
            if (k % 4 == 0) {
                // Cocircular on purpose: the corners of an axis-aligned rectangle.
                const std::int32_t x1 = std::max(a.x, b.x) + 1, y1 = std::max(a.y, b.y) + 1;
                const std::int32_t x0 = std::min(a.x, b.x), y0 = std::min(a.y, b.y);
                a = {x0, y0}, b = {x1, y0}, c = {x1, y1}, d = {x0, y1};
            }
            const int want = reference(a, b, c, d);
            zeros += want == 0 ? 1 : 0;
            CHECK(tb::core::incircle(a, b, c, d) == want);
            ++checked;
        }
    }
    CHECK(checked == 28000);
    CHECK(zeros >= 7000); // the cocircular rectangles
}
