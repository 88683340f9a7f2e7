#pragma once
// Exact geometric predicates on grid points, and the one interpolation rule of the mesher.
// Grid coordinates are at most 2^20 (width and height), so orient2d fits int64 with room to
// spare and incircle uses __int128. No EPS anywhere: every decision is exact.
#include <algorithm>
#include <cstdint>
#include <cstdlib>

#include "core/mesh.hpp"

namespace tb::core {

__extension__ typedef __int128 Int128; // GCC/Clang; __extension__ keeps -Wpedantic quiet

// 1 / orient2d(a, b, c) for interpolate(), computed one way everywhere.
inline double inverse_area(GridPoint a, GridPoint b, GridPoint c);

// Twice the signed area of (a, b, c): > 0 when counter-clockwise in (x, y).
inline std::int64_t orient2d(GridPoint a, GridPoint b, GridPoint c) {
    return (std::int64_t{b.x} - a.x) * (std::int64_t{c.y} - a.y) -
           (std::int64_t{b.y} - a.y) * (std::int64_t{c.x} - a.x);
}

inline double inverse_area(GridPoint a, GridPoint b, GridPoint c) {
    return 1.0 / static_cast<double>(orient2d(a, b, c));
}

// > 0 when d lies strictly inside the circumcircle of the counter-clockwise triangle (a, b, c).
// With every coordinate difference to d below 2^14 (all triangles of a tile, most of a large
// grid) the determinant is below 12 * 2^56 and int64 holds it exactly; otherwise __int128 does.
inline int incircle(GridPoint a, GridPoint b, GridPoint c, GridPoint d) {
    const std::int64_t adx = std::int64_t{a.x} - d.x, ady = std::int64_t{a.y} - d.y;
    const std::int64_t bdx = std::int64_t{b.x} - d.x, bdy = std::int64_t{b.y} - d.y;
    const std::int64_t cdx = std::int64_t{c.x} - d.x, cdy = std::int64_t{c.y} - d.y;
    constexpr std::int64_t kSmall = std::int64_t{1} << 14;
    const auto small = [](std::int64_t v) { return v > -kSmall && v < kSmall; };
    if (small(adx) && small(ady) && small(bdx) && small(bdy) && small(cdx) && small(cdy)) {
        const std::int64_t alift = adx * adx + ady * ady;
        const std::int64_t blift = bdx * bdx + bdy * bdy;
        const std::int64_t clift = cdx * cdx + cdy * cdy;
        const std::int64_t det = alift * (bdx * cdy - cdx * bdy) +
                                 blift * (cdx * ady - adx * cdy) + clift * (adx * bdy - bdx * ady);
        return det > 0 ? 1 : (det < 0 ? -1 : 0);
    }
    using W = Int128;
    const W alift = W{adx} * adx + W{ady} * ady;
    const W blift = W{bdx} * bdx + W{bdy} * bdy;
    const W clift = W{cdx} * cdx + W{cdy} * cdy;
    const W det = alift * (W{bdx} * cdy - W{cdx} * bdy) + blift * (W{cdx} * ady - W{adx} * cdy) +
                  clift * (W{adx} * bdy - W{bdx} * ady);
    return det > 0 ? 1 : (det < 0 ? -1 : 0);
}

// Row-major order of grid points ("a before b" when a comes first in the raster).
inline bool raster_less(GridPoint a, GridPoint b) {
    return a.y != b.y ? a.y < b.y : a.x < b.x;
}

// Height at step k of L along a segment from z0 (k = 0) to z1 (k = L). This is the only way a
// sample on an edge is ever interpolated: it depends on the edge's endpoints alone, so both
// triangles of an edge, the 1-D border fit and the guarantee check all compute the same bits.
inline double lerp_steps(double z0, double z1, std::int64_t k, std::int64_t len) {
    return (z0 * static_cast<double>(len - k) + z1 * static_cast<double>(k)) /
           static_cast<double>(len);
}

// Height of the segment (a, za)-(b, zb) at the grid point p lying on it. The endpoints are put
// in raster order first, so the result does not depend on the edge's direction.
inline double lerp_edge(GridPoint a, double za, GridPoint b, double zb, GridPoint p) {
    if (raster_less(b, a)) {
        const GridPoint tp = a;
        a = b;
        b = tp;
        const double tz = za;
        za = zb;
        zb = tz;
    }
    const std::int64_t len =
        std::max(std::abs(std::int64_t{b.x} - a.x), std::abs(std::int64_t{b.y} - a.y));
    const std::int64_t k =
        std::max(std::abs(std::int64_t{p.x} - a.x), std::abs(std::int64_t{p.y} - a.y));
    return lerp_steps(za, zb, k, len);
}

// The plane of a triangle at a point strictly inside it, from its exact barycentric numerators
// (integers, held exactly in doubles). The only formula for inside points.
inline double interpolate_inside(
    double wa, double wb, double wc, double za, double zb, double zc, double inv_area) {
    return (wa * za + wb * zb + wc * zc) * inv_area;
}
// The same from the integer numerators, each converted exactly.
inline double interpolate_inside(std::int64_t wa,
                                 std::int64_t wb,
                                 std::int64_t wc,
                                 double za,
                                 double zb,
                                 double zc,
                                 double inv_area) {
    return interpolate_inside(static_cast<double>(wa),
                              static_cast<double>(wb),
                              static_cast<double>(wc),
                              za,
                              zb,
                              zc,
                              inv_area);
}

// Height of the triangle (a, b, c) at p, given p's exact barycentric numerators
// wa = orient2d(b, c, p), wb = orient2d(c, a, p), wc = orient2d(a, b, p) (all >= 0) and
// inv_area = 1.0 / orient2d(a, b, c). A point on an edge goes through lerp_edge, a vertex
// returns its height exactly. Every caller passes the same inputs for the same sample and
// triangle, so the error scan and the guarantee check agree to the bit.
inline double interpolate(GridPoint a,
                          double za,
                          GridPoint b,
                          double zb,
                          GridPoint c,
                          double zc,
                          std::int64_t wa,
                          std::int64_t wb,
                          std::int64_t wc,
                          double inv_area,
                          GridPoint p) {
    if (wa == 0 || wb == 0 || wc == 0) {
        if (wa == 0 && wb == 0) {
            return zc;
        }
        if (wb == 0 && wc == 0) {
            return za;
        }
        if (wc == 0 && wa == 0) {
            return zb;
        }
        if (wc == 0) {
            return lerp_edge(a, za, b, zb, p);
        }
        if (wa == 0) {
            return lerp_edge(b, zb, c, zc, p);
        }
        return lerp_edge(c, zc, a, za, p);
    }
    return interpolate_inside(wa, wb, wc, za, zb, zc, inv_area);
}

// floor(n / d) and ceil(n / d) for d > 0 and |n|, d < 2^52 (every caller's values are
// products of two grid coordinates, below 2^42, or a row step times the scan's stride). Exact: both
// are held exactly in doubles, their rounded quotient truncated is floor(n / d) or one more, and
// the remainder says which. A double division pipelines where a 64-bit integer one stalls for tens
// of cycles, and the error scan divides a few times per triangle.
inline std::int64_t floor_div(std::int64_t n, std::int64_t d) {
    const std::int64_t q =
        static_cast<std::int64_t>(static_cast<double>(n) / static_cast<double>(d)); // toward zero
    return n - q * d < 0 ? q - 1 : q;
}
inline std::int64_t ceil_div(std::int64_t n, std::int64_t d) {
    return -floor_div(-n, d);
}

} // namespace tb::core
