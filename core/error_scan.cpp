// Lu & Yun §3.2 "Error Scan": scan-converts a triangle over the grid with exact integer edge
// functions and measures the error of every sample it owns. "The number of error points on a
// triangle edge is recorded separately since they are shared by the two neighboring triangles":
// here each edge sample is owned by exactly one side (owns_edge_samples), so counts add up.
#include "core/error_scan.hpp"

#include <algorithm>
#include <cmath>

#include "core/predicates.hpp"

namespace tb::core {

bool owns_edge_samples(GridPoint a, GridPoint b, int width, int height) {
    const bool boundary = (a.x == 0 && b.x == 0) || (a.y == 0 && b.y == 0) ||
                          (a.x == width - 1 && b.x == width - 1) ||
                          (a.y == height - 1 && b.y == height - 1);
    return boundary || raster_less(a, b);
}

namespace {

// Edge function of p -> q at (x, y): A * x + B(y), the numerator of the opposite vertex's
// barycentric weight. `min` is 0 when the edge's samples are owned, else 1 (strictly inside).
struct EdgeFn {
    std::int64_t a, b0, by; // value = a * x + b0 + by * y
    std::int64_t min;
    EdgeFn(GridPoint p, GridPoint q, bool inclusive) {
        const std::int64_t dx = std::int64_t{q.x} - p.x;
        const std::int64_t dy = std::int64_t{q.y} - p.y;
        a = -dy;
        by = dx;
        b0 = -dx * p.y + dy * p.x;
        min = inclusive ? 0 : 1;
    }
    // Narrows [lo, hi] to the x with value >= min on row y.
    void clip(std::int64_t y, std::int64_t& lo, std::int64_t& hi) const {
        const std::int64_t b = b0 + by * y;
        if (a > 0) {
            lo = std::max(lo, ceil_div(min - b, a));
        } else if (a < 0) {
            hi = std::min(hi, floor_div(b - min, -a));
        } else if (b < min) {
            hi = lo - 1;
        }
    }
};

} // namespace

TriangleStats scan_triangle(const HeightGrid& grid,
                            double eps,
                            GridPoint a,
                            GridPoint b,
                            GridPoint c,
                            std::int64_t stop_at,
                            int stride) {
    TriangleStats st;
    const int w = grid.width;
    const int h = grid.height;
    const EdgeFn fa(b, c, owns_edge_samples(b, c, w, h)); // weight of a
    const EdgeFn fb(c, a, owns_edge_samples(c, a, w, h)); // weight of b
    const EdgeFn fc(a, b, owns_edge_samples(a, b, w, h)); // weight of c
    const double za = grid.at(a.x, a.y);
    const double zb = grid.at(b.x, b.y);
    const double zc = grid.at(c.x, c.y);
    const double inv_area = inverse_area(a, b, c);
    const std::int64_t xmin = std::min({a.x, b.x, c.x});
    const std::int64_t xmax = std::max({a.x, b.x, c.x});
    const std::int64_t ymin = std::min({a.y, b.y, c.y});
    const std::int64_t ymax = std::max({a.y, b.y, c.y});
    const bool masked = !grid.valid.empty();
    const std::int64_t step = stride;
    const std::int64_t first_row = ymin + (step - ymin % step) % step;
    for (std::int64_t y = first_row; y <= ymax; y += step) {
        std::int64_t lo = xmin;
        std::int64_t hi = xmax;
        fa.clip(y, lo, hi);
        fb.clip(y, lo, hi);
        fc.clip(y, lo, hi);
        lo += (step - lo % step) % step;
        if (lo > hi) {
            continue;
        }
        // The weights are integers below 2^53, so doubles hold and step them exactly.
        double wa = static_cast<double>(fa.a * lo + fa.b0 + fa.by * y);
        double wb = static_cast<double>(fb.a * lo + fb.b0 + fb.by * y);
        double wc = static_cast<double>(fc.a * lo + fc.b0 + fc.by * y);
        const double sa = static_cast<double>(fa.a * step), sb = static_cast<double>(fb.a * step),
                     sc = static_cast<double>(fc.a * step);
        const std::size_t row = static_cast<std::size_t>(y) * static_cast<std::size_t>(w);
        const float* heights = grid.heights.data() + row;
        const std::uint8_t* valid = masked ? grid.valid.data() + row : nullptr;
        for (std::int64_t x = lo; x <= hi; x += step, wa += sa, wb += sb, wc += sc) {
            if (masked && valid[x] == 0) {
                continue;
            }
            double z;
            if (wa > 0 && wb > 0 && wc > 0) {
                z = interpolate_inside(wa, wb, wc, za, zb, zc, inv_area);
            } else {
                // On an owned edge, or a vertex (error 0 by definition, not counted).
                const GridPoint p{static_cast<std::int32_t>(x), static_cast<std::int32_t>(y)};
                if (p == a || p == b || p == c) {
                    continue;
                }
                z = interpolate(a,
                                za,
                                b,
                                zb,
                                c,
                                zc,
                                static_cast<std::int64_t>(wa),
                                static_cast<std::int64_t>(wb),
                                static_cast<std::int64_t>(wc),
                                inv_area,
                                p);
            }
            const double err = std::abs(z - static_cast<double>(heights[x]));
            ++st.samples;
            st.total_error += err;
            if (err > st.worst_error) {
                st.worst_error = err;
                st.worst_sample = static_cast<std::int64_t>(row) + x;
            }
            if (err > eps && ++st.error_points >= stop_at) {
                return st;
            }
        }
    }
    return st;
}

} // namespace tb::core
