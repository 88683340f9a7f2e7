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
};

// The x bound that a non-horizontal edge function f puts on rows y0, y0 + step, ...: x >= bound
// when f.a > 0 (a left edge), x <= bound when f.a < 0 (a right edge). Walked row by row with an
// exact integer quotient and remainder, so no division per row: q = floor(n / d) with
// n = b0 + by * y - min and d = |a|; the bound is -q for a left edge (ceil((min - b) / a) =
// -floor((b - min) / a)) and q for a right edge.
class RowBound {
public:
    RowBound() = default;
    RowBound(const EdgeFn& f, std::int64_t y0, std::int64_t step)
        : d_(f.a > 0 ? f.a : -f.a), carry_(f.a > 0 ? -1 : 1) {
        const std::int64_t n = f.b0 + f.by * y0 - f.min;
        const std::int64_t q = floor_div(n, d_);
        r_ = n - q * d_;
        const std::int64_t k = f.by * step;
        const std::int64_t kq = floor_div(k, d_);
        kr_ = k - kq * d_;
        bound_ = carry_ * q;
        step_ = carry_ * kq;
    }
    std::int64_t bound() const { return bound_; }
    // Moves to the next visited row (y + step): q grows by floor(k / d) plus a carry.
    void next() {
        // Both remainders are in [0, d), so one carry at most. Without a branch: the carry
        // pattern of a slope is irregular, and a mispredicted jump per row and edge costs more
        // than the row's samples.
        r_ += kr_;
        const std::int64_t carry = -static_cast<std::int64_t>(r_ >= d_); // all ones or zero
        r_ -= d_ & carry;
        bound_ += step_ + (carry_ & carry);
    }

private:
    std::int64_t d_ = 1, carry_ = 1; // |a|; +1 for a right edge (bound q), -1 for a left (-q)
    std::int64_t r_ = 0, kr_ = 0, bound_ = 0, step_ = 0;
};

// How many visited rows ahead scan_rows prefetches.
constexpr std::int64_t kAhead = 2;

// What both scans need of a triangle: its edge functions (the numerators of a's, b's and c's
// weights, each owning its samples when owns_edge_samples says so), corner heights and 1/area.
struct TriangleFrame {
    GridPoint a, b, c;
    EdgeFn fn[3];
    double za, zb, zc, inv_area;
    TriangleFrame(const HeightGrid& grid, GridPoint pa, GridPoint pb, GridPoint pc)
        : a(pa), b(pb), c(pc),
          fn{EdgeFn(pb, pc, owns_edge_samples(pb, pc, grid.width, grid.height)),  // weight of a
             EdgeFn(pc, pa, owns_edge_samples(pc, pa, grid.width, grid.height)),  // weight of b
             EdgeFn(pa, pb, owns_edge_samples(pa, pb, grid.width, grid.height))}, // weight of c
          za(grid.at(pa.x, pa.y)), zb(grid.at(pb.x, pb.y)), zc(grid.at(pc.x, pc.y)),
          inv_area(inverse_area(pa, pb, pc)) {}

    // The mesh height z at sample (x, y) of the closed triangle, from its weights there; false
    // at a vertex (error 0 by definition, not counted).
    bool surface(std::int64_t x, std::int64_t y, double wa, double wb, double wc, double& z) const {
        if (wa > 0 && wb > 0 && wc > 0) {
            z = interpolate_inside(wa, wb, wc, za, zb, zc, inv_area);
            return true;
        }
        const GridPoint p{static_cast<std::int32_t>(x), static_cast<std::int32_t>(y)};
        if (p == a || p == b || p == c) {
            return false;
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
        return true;
    }
};

// The span of every row is cut by one left and one right edge. A triangle has one long edge
// from its top to its bottom vertex on one side and two edges meeting at its middle vertex on
// the other; on a row above (below) the middle vertex only the upper (lower) of the two can
// bind, since two edge lines cross only on the middle vertex's row. A horizontal edge binds
// only its own row: that row is out when the edge's samples are not owned, and otherwise every
// sample of it lies on the edge.
//
// Within a row's span only the first and the last sample can lie on an edge (an edge function
// grows strictly away from the side it bounds), except on the row of a horizontal edge. So the
// interior samples take the inside formula with no test, and the two ends (and that row) are
// classified exactly.
template <bool kMasked, int kStep>
TriangleStats scan_rows(const HeightGrid& grid,
                        double eps,
                        GridPoint a,
                        GridPoint b,
                        GridPoint c,
                        std::int64_t stop_at,
                        std::int64_t stride) {
    // kStep > 0: the stride is that constant, so its divisions and remainders per row fold
    // into shifts (1: the split agent's full scans, 2: the merge agent's estimates); 0: any.
    const std::int64_t step = kStep > 0 ? kStep : stride;
    const int w = grid.width;
    const TriangleFrame frame(grid, a, b, c);
    const EdgeFn* fn = frame.fn;
    const GridPoint from[3] = {b, c, a}, to[3] = {c, a, b};
    const double za = frame.za, zb = frame.zb, zc = frame.zc, inv_area = frame.inv_area;
    // Running stats in locals (registers in the hot loop); finish() packs them.
    std::int64_t samples = 0, error_points = 0, worst_sample = -1;
    double total_error = 0.0, worst_error = 0.0;
    const auto finish = [&] {
        return TriangleStats{error_points, samples, total_error, worst_error, worst_sample};
    };
    const std::int64_t ymin = std::min({a.y, b.y, c.y});
    const std::int64_t ymax = std::max({a.y, b.y, c.y});
    const std::int64_t first_row = ymin + (step - ymin % step) % step;
    if (first_row > ymax) {
        return finish();
    }
    // The edges: left ones (a > 0) bound x from below, right ones (a < 0) from above. With two
    // on one side, [0] is the upper (smaller y) and [1] the lower; the middle row ymid is
    // where they meet. A horizontal edge's row is hrow; hrow_on says its samples are owned.
    int left[2] = {-1, -1}, right[2] = {-1, -1}, nl = 0, nr = 0;
    std::int64_t hrow = -1;
    bool hrow_on = false;
    for (int k = 0; k < 3; ++k) {
        if (fn[k].a > 0) {
            left[nl++] = k;
        } else if (fn[k].a < 0) {
            right[nr++] = k;
        } else {
            hrow = from[k].y;
            hrow_on = fn[k].min == 0;
        }
    }
    // Rows above ymid use the [0] edges; from ymid on, the two-edge side (pair) switches to its
    // [1] edge. A side with one edge uses it throughout.
    std::int64_t ymid = ymax;
    int* pair = nl == 2 ? left : (nr == 2 ? right : nullptr);
    if (pair != nullptr) {
        const auto top_y = [&](int k) { return std::min(from[k].y, to[k].y); };
        if (top_y(pair[0]) > top_y(pair[1])) {
            std::swap(pair[0], pair[1]);
        }
        ymid = std::max(from[pair[0]].y, to[pair[0]].y);
    }
    // Per visited sample along a row and per visited row: the weights' steps.
    const double sa = static_cast<double>(fn[0].a * step), sb = static_cast<double>(fn[1].a * step),
                 sc = static_cast<double>(fn[2].a * step);
    const std::int64_t da = fn[0].by * step, db = fn[1].by * step, dc = fn[2].by * step;
    // The weights at x = 0 on row y (b0 + by * y), stepped exactly from row to row.
    std::int64_t ra = fn[0].b0 + fn[0].by * first_row, rb = fn[1].b0 + fn[1].by * first_row,
                 rc = fn[2].b0 + fn[2].by * first_row;
    const auto align = [&](std::int64_t x) { return step == 1 ? x : x + (step - x % step) % step; };
    // The first visited row from which the two-edge side is cut by its lower edge. On the
    // middle row itself the upper one excludes at most the middle vertex, never scanned.
    const std::int64_t switch_row =
        pair != nullptr ? ymid + (step - ymid % step) % step : INT64_MAX;
    RowBound lb(fn[left[0]], first_row, step), rbd(fn[right[0]], first_row, step);
    for (std::int64_t y = first_row; y <= ymax;
         y += step, lb.next(), rbd.next(), ra += da, rb += db, rc += dc) {
        if (y == switch_row) {
            (pair == left ? lb : rbd) = RowBound(fn[pair[1]], y, step);
        }
        if (y == hrow && !hrow_on) {
            continue;
        }
        const std::int64_t lo = align(lb.bound());
        const std::int64_t hi = rbd.bound();
        if (lo > hi) {
            continue;
        }
        const std::int64_t last = step == 1 ? hi : lo + (hi - lo) / step * step; // last visited
        // The weights are integers below 2^53, so doubles hold and step them exactly.
        double wa = static_cast<double>(fn[0].a * lo + ra);
        double wb = static_cast<double>(fn[1].a * lo + rb);
        double wc = static_cast<double>(fn[2].a * lo + rc);
        const std::size_t row = static_cast<std::size_t>(y) * static_cast<std::size_t>(w);
        const float* heights = grid.heights.data() + row;
        // Rows are a grid width apart in memory, too far for the hardware prefetcher: ask for
        // the row kAhead steps down now (its span there is close to this row's).
        if (y + kAhead * step <= ymax) {
            const float* ahead = heights + kAhead * step * w;
            __builtin_prefetch(ahead + lo);
            __builtin_prefetch(ahead + last);
        }
        const std::uint8_t* valid = kMasked ? grid.valid.data() + row : nullptr;
        // Records the error of sample x; true when the scan must stop (stats then partial).
        // Inlined, so that the running stats stay in registers.
        const auto record = [&](std::int64_t x, double z) __attribute__((always_inline)) {
            const double err = std::abs(z - static_cast<double>(heights[x]));
            ++samples;
            total_error += err;
            // Counted without a branch: at coarse eps error points and clean samples mix.
            error_points += err > eps ? 1 : 0;
            if (err > worst_error) {
                worst_error = err;
                worst_sample = static_cast<std::int64_t>(row) + x;
            }
            return error_points >= stop_at;
        };
        // Sample x at the current weights, anywhere in the closed triangle.
        const auto classify = [&](std::int64_t x) __attribute__((always_inline)) {
            if (kMasked && valid[x] == 0) {
                return false;
            }
            double z;
            // Off the hot path: only span ends and horizontal edges come here.
            if (!frame.surface(x, y, wa, wb, wc, z)) {
                return false;
            }
            return record(x, z);
        };
        if (y == hrow) {
            // Every sample of the row lies on the horizontal edge.
            for (std::int64_t x = lo; x <= last; x += step, wa += sa, wb += sb, wc += sc) {
                if (classify(x)) {
                    return finish();
                }
            }
            continue;
        }
        if (classify(lo)) {
            return finish();
        }
        if (last == lo) {
            continue;
        }
        wa += sa, wb += sb, wc += sc;
        for (std::int64_t x = lo + step; x < last; x += step, wa += sa, wb += sb, wc += sc) {
            if (kMasked && valid[x] == 0) {
                continue;
            }
            if (record(x, interpolate_inside(wa, wb, wc, za, zb, zc, inv_area))) {
                return finish();
            }
        }
        if (classify(last)) {
            return finish();
        }
    }
    return finish();
}

// Triangles whose bounding box holds at most kSmallBox samples are scanned over the box: a
// test of the three edge functions per sample instead of scan_rows' per-row bounds, whose
// set-up (a division per bound) costs more than such a triangle's few samples. The same samples
// in the same order with the same formulas: the same stats as scan_rows, bit for bit.
constexpr std::int64_t kSmallBox = 48;

template <bool kMasked>
TriangleStats scan_box(const HeightGrid& grid,
                       double eps,
                       GridPoint a,
                       GridPoint b,
                       GridPoint c,
                       std::int64_t stop_at) {
    const int w = grid.width;
    const TriangleFrame frame(grid, a, b, c);
    const EdgeFn* fn = frame.fn;
    std::int64_t samples = 0, error_points = 0, worst_sample = -1;
    double total_error = 0.0, worst_error = 0.0;
    const std::int32_t x0 = std::min({a.x, b.x, c.x}), x1 = std::max({a.x, b.x, c.x});
    const std::int32_t y0 = std::min({a.y, b.y, c.y}), y1 = std::max({a.y, b.y, c.y});
    for (std::int32_t y = y0; y <= y1; ++y) {
        const std::size_t row = static_cast<std::size_t>(y) * static_cast<std::size_t>(w);
        std::int64_t wa = fn[0].a * x0 + fn[0].b0 + fn[0].by * y;
        std::int64_t wb = fn[1].a * x0 + fn[1].b0 + fn[1].by * y;
        std::int64_t wc = fn[2].a * x0 + fn[2].b0 + fn[2].by * y;
        for (std::int32_t x = x0; x <= x1; ++x, wa += fn[0].a, wb += fn[1].a, wc += fn[2].a) {
            if (wa < fn[0].min || wb < fn[1].min || wc < fn[2].min ||
                (kMasked && grid.valid[row + static_cast<std::size_t>(x)] == 0)) {
                continue;
            }
            // The weights are integers below 2^53: exact as doubles, the same z as scan_rows.
            double z;
            if (!frame.surface(x,
                               y,
                               static_cast<double>(wa),
                               static_cast<double>(wb),
                               static_cast<double>(wc),
                               z)) {
                continue;
            }
            const double err =
                std::abs(z - static_cast<double>(grid.heights[row + static_cast<std::size_t>(x)]));
            ++samples;
            total_error += err;
            error_points += err > eps ? 1 : 0;
            if (err > worst_error) {
                worst_error = err;
                worst_sample = static_cast<std::int64_t>(row) + x;
            }
            if (error_points >= stop_at) {
                return TriangleStats{error_points, samples, total_error, worst_error, worst_sample};
            }
        }
    }
    return TriangleStats{error_points, samples, total_error, worst_error, worst_sample};
}

} // namespace

TriangleStats scan_triangle(const HeightGrid& grid,
                            double eps,
                            GridPoint a,
                            GridPoint b,
                            GridPoint c,
                            std::int64_t stop_at,
                            int stride) {
    // Masked and unmasked grids and the common strides get separate loops: the validity test
    // and the stride arithmetic leave the hot path.
    const bool masked = !grid.valid.empty();
    const std::int64_t box =
        (std::int64_t{std::max({a.x, b.x, c.x})} - std::min({a.x, b.x, c.x}) + 1) *
        (std::int64_t{std::max({a.y, b.y, c.y})} - std::min({a.y, b.y, c.y}) + 1);
    if (stride == 1 && box <= kSmallBox) {
        return masked ? scan_box<true>(grid, eps, a, b, c, stop_at)
                      : scan_box<false>(grid, eps, a, b, c, stop_at);
    }
    switch (stride) {
    case 1:
        return masked ? scan_rows<true, 1>(grid, eps, a, b, c, stop_at, 1)
                      : scan_rows<false, 1>(grid, eps, a, b, c, stop_at, 1);
    case 2:
        return masked ? scan_rows<true, 2>(grid, eps, a, b, c, stop_at, 2)
                      : scan_rows<false, 2>(grid, eps, a, b, c, stop_at, 2);
    default:
        return masked ? scan_rows<true, 0>(grid, eps, a, b, c, stop_at, stride)
                      : scan_rows<false, 0>(grid, eps, a, b, c, stop_at, stride);
    }
}

} // namespace tb::core
