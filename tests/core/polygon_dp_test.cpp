// §3.4 polygon DP: its optimum equals the best of all triangulations, enumerated by brute force.
#include <doctest/doctest.h>

#include <cmath>
#include <functional>
#include <limits>
#include <optional>
#include <vector>

#include "core/polygon_dp.hpp"
#include "tests/core/terrains.hpp"

namespace {

using tb::core::GridPoint;

std::int64_t cross(GridPoint a, GridPoint b, GridPoint c) {
    return (std::int64_t{b.x} - a.x) * (std::int64_t{c.y} - a.y) -
           (std::int64_t{b.y} - a.y) * (std::int64_t{c.x} - a.x);
}

// Triangle (i, j, k) lies inside the polygon: counter-clockwise, no other polygon vertex in
// its closed area, and no polygon edge crossing one of its sides (tested by sampling edges'
// intersections exactly).
bool triangle_inside(const std::vector<GridPoint>& v, int i, int j, int k) {
    const GridPoint a = v[static_cast<std::size_t>(i)], b = v[static_cast<std::size_t>(j)],
                    c = v[static_cast<std::size_t>(k)];
    if (cross(a, b, c) <= 0) {
        return false;
    }
    const int n = static_cast<int>(v.size());
    for (int m = 0; m < n; ++m) {
        if (m == i || m == j || m == k) {
            continue;
        }
        const GridPoint p = v[static_cast<std::size_t>(m)];
        if (cross(a, b, p) >= 0 && cross(b, c, p) >= 0 && cross(c, a, p) >= 0) {
            return false;
        }
    }
    // A polygon edge crossing a side properly.
    const GridPoint tri[3] = {a, b, c};
    for (int m = 0; m < n; ++m) {
        const GridPoint p = v[static_cast<std::size_t>(m)],
                        q = v[static_cast<std::size_t>((m + 1) % n)];
        for (int s = 0; s < 3; ++s) {
            const GridPoint u = tri[s], w = tri[(s + 1) % 3];
            const auto d1 = cross(u, w, p), d2 = cross(u, w, q), d3 = cross(p, q, u),
                       d4 = cross(p, q, w);
            if (((d1 > 0 && d2 < 0) || (d1 < 0 && d2 > 0)) &&
                ((d3 > 0 && d4 < 0) || (d3 < 0 && d4 > 0))) {
                return false;
            }
        }
    }
    // A side that runs outside between two vertices: its midpoint must be inside the polygon.
    for (int s = 0; s < 3; ++s) {
        const GridPoint u = tri[s], w = tri[(s + 1) % 3];
        // Winding number of the doubled midpoint (2u + 2w) / 2 against the doubled polygon.
        const std::int64_t mx = std::int64_t{u.x} + w.x, my = std::int64_t{u.y} + w.y;
        int wn = 0;
        bool on_edge = false;
        for (int m = 0; m < n; ++m) {
            const GridPoint p = v[static_cast<std::size_t>(m)],
                            q = v[static_cast<std::size_t>((m + 1) % n)];
            const std::int64_t px = 2 * p.x, py = 2 * p.y, qx = 2 * q.x, qy = 2 * q.y;
            const std::int64_t side = (qx - px) * (my - py) - (qy - py) * (mx - px);
            if (side == 0 && std::min(px, qx) <= mx && mx <= std::max(px, qx) &&
                std::min(py, qy) <= my && my <= std::max(py, qy)) {
                on_edge = true;
            }
            if (py <= my) {
                if (qy > my && side > 0) {
                    ++wn;
                }
            } else if (qy <= my && side < 0) {
                --wn;
            }
        }
        if (!on_edge && wn == 0) {
            return false;
        }
    }
    return true;
}

// Minimum cost over all triangulations of the sub-polygon i..k (edge i-k closing it).
std::optional<double> brute(const std::vector<GridPoint>& v,
                            int i,
                            int k,
                            const std::function<std::optional<double>(int, int, int)>& cost) {
    if (k - i < 2) {
        return 0.0;
    }
    std::optional<double> best;
    for (int j = i + 1; j < k; ++j) {
        if (!triangle_inside(v, i, j, k)) {
            continue;
        }
        const auto c = cost(i, j, k);
        const auto l = brute(v, i, j, cost);
        const auto r = brute(v, j, k, cost);
        if (c && l && r && (!best || *c + *l + *r < *best)) {
            best = *c + *l + *r;
        }
    }
    return best;
}

} // namespace

TEST_CASE("the polygon DP equals brute force on random star-shaped polygons (seeds 1-200)") {
    for (std::uint64_t seed = 1; seed <= 200; ++seed) {
        terrain::Lcg r(seed);
        const int n = 3 + static_cast<int>(r.next() * 6);
        // A star-shaped polygon around the origin, like the hole left by a removed vertex,
        // with some collinear vertices from coarse radii.
        std::vector<GridPoint> v;
        for (int k = 0; k < n; ++k) {
            const double ang = 2 * 3.14159265358979 * (k + 0.3 * r.next()) / n;
            const double rad = 2 + std::floor(r.next() * 6);
            v.push_back({static_cast<std::int32_t>(std::lround(rad * std::cos(ang))),
                         static_cast<std::int32_t>(std::lround(rad * std::sin(ang)))});
        }
        bool simple = true; // rounding can fold the polygon; skip those
        for (int k = 0; k < n && simple; ++k) {
            const GridPoint a = v[static_cast<std::size_t>(k)],
                            b = v[static_cast<std::size_t>((k + 1) % n)];
            simple = !(a == b) && cross({0, 0}, a, b) > 0;
        }
        if (!simple) {
            continue;
        }
        std::vector<double> table(static_cast<std::size_t>(n * n * n));
        for (auto& c : table) {
            c = std::floor(r.next() * 1000.0);
        }
        const bool forbid = seed % 4 == 0;
        auto cost = [&](int i, int j, int k) -> std::optional<double> {
            const double c = table[static_cast<std::size_t>((i * n + j) * n + k)];
            if (forbid && c < 100.0) {
                return std::nullopt;
            }
            return c;
        };
        tb::core::TriangleCost total;
        const auto tris = tb::core::triangulate_polygon(
            v,
            [&](int i, int j, int k) -> std::optional<tb::core::TriangleCost> {
                const auto c = cost(i, j, k);
                if (!c) {
                    return std::nullopt;
                }
                return tb::core::TriangleCost{0, *c};
            },
            &total);
        const auto expect = brute(v, 0, n - 1, cost);
        INFO("seed=", seed, " n=", n);
        REQUIRE(tris.has_value() == expect.has_value());
        if (!expect) {
            continue;
        }
        CHECK(total.error == *expect);
        CHECK(tris->size() == static_cast<std::size_t>(n - 2));
        std::int64_t area = 0, want = 0;
        for (const auto& [i, j, k] : *tris) {
            area += cross(v[static_cast<std::size_t>(i)],
                          v[static_cast<std::size_t>(j)],
                          v[static_cast<std::size_t>(k)]);
        }
        for (int k = 0; k < n; ++k) {
            want += cross(
                {0, 0}, v[static_cast<std::size_t>(k)], v[static_cast<std::size_t>((k + 1) % n)]);
        }
        CHECK(area == want);
    }
}

TEST_CASE("a diagonal through a straight vertex or outside a reflex corner is not valid") {
    // Square with a vertex in the middle of its bottom side (straight angle at 1).
    const std::vector<GridPoint> sq{{0, 0}, {2, 0}, {4, 0}, {4, 4}, {0, 4}};
    CHECK_FALSE(tb::core::valid_diagonal(sq, 0, 2)); // runs along the side through vertex 1
    CHECK(tb::core::valid_diagonal(sq, 1, 3));
    CHECK(tb::core::valid_diagonal(sq, 1, 4));
    // An arrow: the diagonal between the two barbs passes outside the reflex notch.
    const std::vector<GridPoint> arrow{{0, 0}, {4, 2}, {0, 4}, {1, 2}};
    CHECK_FALSE(tb::core::valid_diagonal(arrow, 0, 2));
    CHECK(tb::core::valid_diagonal(arrow, 1, 3));
}

TEST_CASE("the star-shaped diagonal test agrees with the general one (seeds 1-400)") {
    for (std::uint64_t seed = 1; seed <= 400; ++seed) {
        terrain::Lcg r(seed);
        const int n = 3 + static_cast<int>(r.next() * 9);
        const bool border = seed % 3 == 0;
        // Vertices in strictly increasing angle around the origin; for a border hole they span
        // a half turn, first and last on the x axis (the origin on the closing edge).
        std::vector<GridPoint> v;
        for (int k = 0; k < n; ++k) {
            const double ang = border ? 3.14159265358979 * k / (n - 1)
                                      : 2 * 3.14159265358979 * (k + 0.4 * r.next()) / n;
            const double rad = 2 + std::floor(r.next() * 7);
            v.push_back({static_cast<std::int32_t>(std::lround(rad * std::cos(ang))),
                         static_cast<std::int32_t>(std::lround(rad * std::sin(ang)))});
        }
        if (border) {
            v.front().y = 0;
            v.back().y = 0;
        }
        bool star = true; // rounding can break the star shape; skip those
        for (int k = 0; k < n && star; ++k) {
            const GridPoint a = v[static_cast<std::size_t>(k)];
            const GridPoint b = v[static_cast<std::size_t>((k + 1) % n)];
            const bool closing = border && k == n - 1;
            star = !(a == b) && (closing ? cross(a, b, {0, 0}) == 0 && a.x < 0 && b.x > 0
                                         : cross(a, b, {0, 0}) > 0);
        }
        if (!star) {
            continue;
        }
        for (int i = 0; i < n; ++i) {
            for (int j = i + 2; j < n; ++j) {
                if (i == 0 && j == n - 1) {
                    continue; // a polygon edge
                }
                INFO("seed=", seed, " n=", n, " i=", i, " j=", j);
                CHECK(tb::core::valid_diagonal_star(v, {0, 0}, i, j) ==
                      tb::core::valid_diagonal(v, i, j));
            }
        }
    }
}
