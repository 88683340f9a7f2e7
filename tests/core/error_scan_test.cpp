// §3.2 Error scan: scan_triangle against a brute-force walk of the triangle's bounding box, and
// the ownership rule as a partition of the grid's samples.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "core/delaunay.hpp"
#include "core/error_scan.hpp"
#include "core/predicates.hpp"
#include "tests/core/terrains.hpp"

namespace {

using tb::core::GridPoint;
using tb::core::HeightGrid;
using tb::core::TriangleStats;

// The samples of the bounding box in raster order, each tested on its own with orient2d: inside,
// or on an edge that owns its samples; never a vertex. Stops after the stop_at-th error point,
// as the scan promises.
TriangleStats brute_scan(const HeightGrid& g,
                         double eps,
                         GridPoint a,
                         GridPoint b,
                         GridPoint c,
                         std::int64_t stop_at,
                         int stride) {
    using namespace tb::core;
    TriangleStats st;
    const double za = g.at(a.x, a.y), zb = g.at(b.x, b.y), zc = g.at(c.x, c.y);
    const double inv_area = inverse_area(a, b, c);
    const int y0 = std::min({a.y, b.y, c.y}), y1 = std::max({a.y, b.y, c.y});
    const int x0 = std::min({a.x, b.x, c.x}), x1 = std::max({a.x, b.x, c.x});
    for (int y = y0; y <= y1; ++y) {
        for (int x = x0; x <= x1; ++x) {
            if (x % stride != 0 || y % stride != 0 || !g.is_valid(x, y)) {
                continue;
            }
            const GridPoint p{x, y};
            if (p == a || p == b || p == c) {
                continue;
            }
            const std::int64_t wa = orient2d(b, c, p), wb = orient2d(c, a, p),
                               wc = orient2d(a, b, p);
            if (wa < 0 || wb < 0 || wc < 0 ||
                (wa == 0 && !owns_edge_samples(b, c, g.width, g.height)) ||
                (wb == 0 && !owns_edge_samples(c, a, g.width, g.height)) ||
                (wc == 0 && !owns_edge_samples(a, b, g.width, g.height))) {
                continue;
            }
            const double z = interpolate(a, za, b, zb, c, zc, wa, wb, wc, inv_area, p);
            const double err = std::abs(z - static_cast<double>(g.at(x, y)));
            ++st.samples;
            st.total_error += err;
            if (err > st.worst_error) {
                st.worst_error = err;
                st.worst_sample = std::int64_t{y} * g.width + x;
            }
            if (err > eps && ++st.error_points >= stop_at) {
                return st;
            }
        }
    }
    return st;
}

void check_same(const TriangleStats& got, const TriangleStats& want) {
    CHECK(got.samples == want.samples);
    CHECK(got.error_points == want.error_points);
    CHECK(got.worst_sample == want.worst_sample);
    CHECK(got.worst_error == want.worst_error);
    // Same samples, same order, same formula: the sums agree to the bit.
    CHECK(got.total_error == want.total_error);
}

GridPoint random_point(terrain::Lcg& r, int w, int h) {
    return {static_cast<std::int32_t>(r.next() * w), static_cast<std::int32_t>(r.next() * h)};
}

} // namespace

TEST_CASE("floor_div and ceil_div round exactly, near multiples and up to 2^42") {
    // The reference: integer division, corrected toward minus infinity.
    const auto floor_ref = [](std::int64_t n, std::int64_t d) {
        const std::int64_t q = n / d;
        return (n % d != 0 && n < 0) ? q - 1 : q;
    };
    terrain::Lcg r(42);
    for (int i = 0; i < 2000000; ++i) {
        const int bits_d = 1 + static_cast<int>(r.next() * 21);
        const int bits_n = 1 + static_cast<int>(r.next() * 42);
        const std::int64_t d = 1 + static_cast<std::int64_t>(r.next() * std::ldexp(1.0, bits_d));
        std::int64_t n = static_cast<std::int64_t>(r.next() * std::ldexp(1.0, bits_n));
        if (i % 3 == 0) {
            n = n / d * d + static_cast<std::int64_t>(r.next() * 3) - 1; // next to a multiple
        }
        if (i % 2 == 1) {
            n = -n;
        }
        REQUIRE(tb::core::floor_div(n, d) == floor_ref(n, d));
        REQUIRE(tb::core::ceil_div(n, d) == -floor_ref(-n, d));
    }
    const std::int64_t big = std::int64_t{1} << 42;
    for (std::int64_t d :
         {std::int64_t{1}, std::int64_t{3}, std::int64_t{1} << 20, (std::int64_t{1} << 21) - 1}) {
        for (std::int64_t n : {big - 1, big, big + 1, -big - 1, -big, -big + 1, std::int64_t{0}}) {
            CHECK(tb::core::floor_div(n, d) == floor_ref(n, d));
            CHECK(tb::core::ceil_div(n, d) == -floor_ref(-n, d));
        }
    }
}

TEST_CASE("scan_triangle equals a brute-force walk of the bounding box (seeds 1-3000)") {
    for (std::uint64_t seed = 1; seed <= 3000; ++seed) {
        terrain::Lcg r(seed);
        // Small grids make boundary edges, horizontal and vertical edges and slivers common.
        const int w = 2 + static_cast<int>(r.next() * 40), h = 2 + static_cast<int>(r.next() * 40);
        HeightGrid g = terrain::noise(w, h, seed, 30.0, 4.0);
        if (seed % 3 == 0) {
            g.valid.resize(g.heights.size());
            for (auto& v : g.valid) {
                v = r.next() < 0.8 ? 1 : 0;
            }
        }
        GridPoint a = random_point(r, w, h), b = random_point(r, w, h), c = random_point(r, w, h);
        if (seed % 4 == 1) {
            b.y = a.y; // a horizontal edge
        } else if (seed % 4 == 2) {
            c.x = b.x; // a vertical edge
        }
        std::int64_t area = tb::core::orient2d(a, b, c);
        if (area == 0) {
            continue;
        }
        if (area < 0) {
            std::swap(b, c);
        }
        const double eps = 0.5 + r.next() * 4.0;
        const int stride = seed % 5 == 0 ? 2 + static_cast<int>(seed % 3) : 1;
        const std::int64_t stop_at =
            seed % 7 == 0 ? 1 + static_cast<std::int64_t>(seed % 5) : INT64_MAX;
        CAPTURE(seed);
        CAPTURE(w);
        CAPTURE(h);
        CAPTURE(stride);
        CAPTURE(stop_at);
        check_same(tb::core::scan_triangle(g, eps, a, b, c, stop_at, stride),
                   brute_scan(g, eps, a, b, c, stop_at, stride));
    }
}

TEST_CASE("scan_triangle on long thin triangles and large grids (seeds 1-300)") {
    for (std::uint64_t seed = 1; seed <= 300; ++seed) {
        terrain::Lcg r(seed);
        const int w = 300, h = 300;
        const HeightGrid g = terrain::noise(w, h, seed, 100.0, 2.0);
        // A sliver: two nearby points and a far one.
        const GridPoint a = random_point(r, w, h);
        const GridPoint b{std::min(w - 1, a.x + 1 + static_cast<int>(r.next() * 3)),
                          std::min(h - 1, a.y + static_cast<int>(r.next() * 2))};
        GridPoint c = random_point(r, w, h);
        const std::int64_t area = tb::core::orient2d(a, b, c);
        if (area == 0) {
            continue;
        }
        const GridPoint p = area > 0 ? b : c, q = area > 0 ? c : b;
        CAPTURE(seed);
        check_same(tb::core::scan_triangle(g, 1.0, a, p, q),
                   brute_scan(g, 1.0, a, p, q, INT64_MAX, 1));
    }
}

TEST_CASE("every non-vertex sample has exactly one owner in a triangulation (seeds 1-40)") {
    for (std::uint64_t seed = 1; seed <= 40; ++seed) {
        terrain::Lcg r(seed);
        const int w = 2 + static_cast<int>(r.next() * 50), h = 2 + static_cast<int>(r.next() * 50);
        const HeightGrid g = terrain::noise(w, h, seed, 40.0, 3.0);
        std::vector<GridPoint> pts;
        const int n = static_cast<int>(r.next() * w * h / 6);
        for (int i = 0; i < n; ++i) {
            pts.push_back(random_point(r, w, h));
        }
        const tb::core::Tin tin = tb::core::delaunay_rectangle(w, h, pts);
        const tb::core::Mesh m = tin.to_mesh(g.heights, w);
        std::int64_t samples = 0, error_points = 0;
        for (std::size_t t = 0; t < m.triangle_count(); ++t) {
            const TriangleStats st = tb::core::scan_triangle(g,
                                                             1.0,
                                                             m.points[m.triangles[3 * t]],
                                                             m.points[m.triangles[3 * t + 1]],
                                                             m.points[m.triangles[3 * t + 2]]);
            samples += st.samples;
            error_points += st.error_points;
        }
        CAPTURE(seed);
        CHECK(samples + static_cast<std::int64_t>(m.points.size()) == std::int64_t{w} * h);
        // The brute count of error points: any closed triangle containing a sample gives its
        // mesh height (edge samples interpolate from the edge alone).
        std::int64_t want = 0;
        for (int y = 0; y < h; ++y) {
            for (int x = 0; x < w; ++x) {
                const GridPoint p{x, y};
                for (std::size_t t = 0; t < m.triangle_count(); ++t) {
                    const GridPoint a = m.points[m.triangles[3 * t]],
                                    b = m.points[m.triangles[3 * t + 1]],
                                    c = m.points[m.triangles[3 * t + 2]];
                    const std::int64_t wa = tb::core::orient2d(b, c, p),
                                       wb = tb::core::orient2d(c, a, p),
                                       wc = tb::core::orient2d(a, b, p);
                    if (wa < 0 || wb < 0 || wc < 0) {
                        continue;
                    }
                    const double z = tb::core::interpolate(a,
                                                           g.at(a.x, a.y),
                                                           b,
                                                           g.at(b.x, b.y),
                                                           c,
                                                           g.at(c.x, c.y),
                                                           wa,
                                                           wb,
                                                           wc,
                                                           tb::core::inverse_area(a, b, c),
                                                           p);
                    want += std::abs(z - static_cast<double>(g.at(x, y))) > 1.0 ? 1 : 0;
                    break;
                }
            }
        }
        CHECK(error_points == want);
    }
}
