// Lu & Yun §3.4 (figure 5c): "A dynamic programming algorithm is formulated for constructing
// such optimal polygon triangulation", after Klincsek: F(i, k) = min over j of
// F(i, j) + F(j, k) + f(v_i, v_j, v_k), with F = +inf across invalid diagonals.
#include "core/polygon_dp.hpp"

#include <utility>

#include "core/predicates.hpp"

namespace tb::core {
namespace {

int sign(std::int64_t v) {
    return v > 0 ? 1 : (v < 0 ? -1 : 0);
}

// p lies on the closed segment [a, b] (given collinear).
bool within(GridPoint a, GridPoint b, GridPoint p) {
    return std::min(a.x, b.x) <= p.x && p.x <= std::max(a.x, b.x) && std::min(a.y, b.y) <= p.y &&
           p.y <= std::max(a.y, b.y);
}

// Closed segments [a, b] and [c, d] share at least one point.
bool segments_touch(GridPoint a, GridPoint b, GridPoint c, GridPoint d) {
    const int o1 = sign(orient2d(a, b, c)), o2 = sign(orient2d(a, b, d));
    const int o3 = sign(orient2d(c, d, a)), o4 = sign(orient2d(c, d, b));
    if (o1 * o2 < 0 && o3 * o4 < 0) {
        return true;
    }
    return (o1 == 0 && within(a, b, c)) || (o2 == 0 && within(a, b, d)) ||
           (o3 == 0 && within(c, d, a)) || (o4 == 0 && within(c, d, b));
}

// b lies strictly inside the interior angle of the polygon at vertex a (between the edges to
// prev and next), never on either edge's ray.
bool in_cone(GridPoint prev, GridPoint a, GridPoint next, GridPoint b) {
    const std::int64_t to_next = orient2d(a, next, b); // > 0: b left of a -> next
    const std::int64_t to_prev = orient2d(a, prev, b); // < 0: b right of a -> prev
    if (orient2d(prev, a, next) > 0) { // convex corner: strictly between the two edges
        return to_next > 0 && to_prev < 0;
    }
    // Reflex or straight corner: anywhere but the closed exterior wedge.
    return to_next > 0 || to_prev < 0;
}

} // namespace

bool valid_diagonal(std::span<const GridPoint> v, int i, int j) {
    const int n = static_cast<int>(v.size());
    auto at = [&](int k) { return v[static_cast<std::size_t>((k % n + n) % n)]; };
    if (!in_cone(at(i - 1), at(i), at(i + 1), at(j)) ||
        !in_cone(at(j - 1), at(j), at(j + 1), at(i))) {
        return false;
    }
    const GridPoint a = at(i), b = at(j);
    for (int k = 0; k < n; ++k) {
        const int k1 = (k + 1) % n;
        if (k == i || k == j || k1 == i || k1 == j) {
            continue;
        }
        if (segments_touch(a, b, at(k), at(k1))) {
            return false;
        }
    }
    return true;
}

bool valid_diagonal_star(std::span<const GridPoint> v, GridPoint center, int i, int j) {
    const int n = static_cast<int>(v.size());
    if (i > j) {
        std::swap(i, j);
    }
    const GridPoint a = v[static_cast<std::size_t>(i)], b = v[static_cast<std::size_t>(j)];
    const std::int64_t side = orient2d(a, b, center);
    if (side == 0) {
        // Through center, which sees every vertex and shares no angle between two of them:
        // inside. (A border hole's closing edge lies this way, but it is a polygon edge.)
        return true;
    }
    // The vertices go round center in strictly increasing angle. With center left of a -> b
    // the chain i+1..j-1 spans less than a half turn and the segment faces it; otherwise the
    // chain j+1..i-1 (wrapping) does. That chain must lie strictly beyond the segment.
    const bool inner = side > 0;
    const int first = inner ? i + 1 : j + 1;
    const int count = inner ? j - i - 1 : n - (j - i) - 1;
    for (int s = 0; s < count; ++s) {
        const std::int64_t o = orient2d(a, b, v[static_cast<std::size_t>((first + s) % n)]);
        if (o == 0 || (o > 0) == (side > 0)) {
            return false;
        }
    }
    return true;
}

} // namespace tb::core
