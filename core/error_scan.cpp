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

// The x bound that edge function f puts on rows y0, y0 + step, ...: x >= lo_bound when f.a > 0,
// x <= hi_bound when f.a < 0, no x at all when f.a == 0 and the row is outside. Walked row by
// row with an exact integer quotient and remainder, so no division per row:
// q = floor(n / d) with n = b0 + by * y - min and d = |a| (then the bound is -q for a > 0,
// since ceil((min - b) / a) = -floor((b - min) / a), and q for a < 0).
class RowBound {
public:
    RowBound(const EdgeFn& f, std::int64_t y0, std::int64_t step) : a_(f.a), n_(0) {
        const std::int64_t n = f.b0 + f.by * y0 - f.min;
        if (a_ == 0) {
            n_ = n; // the row is inside when n >= 0
            dn_ = f.by * step;
            return;
        }
        d_ = a_ > 0 ? a_ : -a_;
        q_ = floor_div(n, d_);
        r_ = n - q_ * d_;
        const std::int64_t k = f.by * step;
        kq_ = floor_div(k, d_);
        kr_ = k - kq_ * d_;
    }
    // Narrows [lo, hi] to the x the edge allows on the current row.
    void clip(std::int64_t& lo, std::int64_t& hi) const {
        if (a_ > 0) {
            lo = std::max(lo, -q_);
        } else if (a_ < 0) {
            hi = std::min(hi, q_);
        } else if (n_ < 0) {
            hi = lo - 1;
        }
    }
    // Moves to the next visited row (y + step).
    void next() {
        if (a_ == 0) {
            n_ += dn_;
            return;
        }
        q_ += kq_;
        r_ += kr_; // both remainders in [0, d), so one carry at most
        if (r_ >= d_) {
            r_ -= d_;
            ++q_;
        }
    }

private:
    std::int64_t a_;
    bool inclusive_;          // min == 0: the edge's own samples are in
    std::int64_t n_, dn_ = 0; // a == 0: value - min on the row, its step
    std::int64_t d_ = 1, q_ = 0, r_ = 0, kq_ = 0, kr_ = 0; // a != 0
};

// How many visited rows ahead scan_rows prefetches.
constexpr std::int64_t kAhead = 2;

template <bool kMasked>
TriangleStats scan_rows(const HeightGrid& grid,
                        double eps,
                        GridPoint a,
                        GridPoint b,
                        GridPoint c,
                        std::int64_t stop_at,
                        std::int64_t step) {
    const int w = grid.width;
    const int h = grid.height;
    const EdgeFn fa(b, c, owns_edge_samples(b, c, w, h)); // weight of a
    const EdgeFn fb(c, a, owns_edge_samples(c, a, w, h)); // weight of b
    const EdgeFn fc(a, b, owns_edge_samples(a, b, w, h)); // weight of c
    const double za = grid.at(a.x, a.y);
    const double zb = grid.at(b.x, b.y);
    const double zc = grid.at(c.x, c.y);
    const double inv_area = inverse_area(a, b, c);
    // Running stats in locals (registers in the hot loop); finish() packs them.
    std::int64_t samples = 0, error_points = 0, worst_sample = -1;
    double total_error = 0.0, worst_error = 0.0;
    // min(worst_error, eps): a sample whose error is not above it only adds to the sums.
    double gate = 0.0;
    const auto finish = [&] {
        return TriangleStats{error_points, samples, total_error, worst_error, worst_sample};
    };
    const std::int64_t xmin = std::min({a.x, b.x, c.x});
    const std::int64_t xmax = std::max({a.x, b.x, c.x});
    const std::int64_t ymin = std::min({a.y, b.y, c.y});
    const std::int64_t ymax = std::max({a.y, b.y, c.y});
    const std::int64_t first_row = ymin + (step - ymin % step) % step;
    const auto align = [step](std::int64_t x) {
        return step == 1 ? x : x + (step - x % step) % step;
    };
    RowBound ba(fa, first_row, step), bb(fb, first_row, step), bc(fc, first_row, step);
    // Per visited sample along a row and per visited row: the weights' steps.
    const double sa = static_cast<double>(fa.a * step), sb = static_cast<double>(fb.a * step),
                 sc = static_cast<double>(fc.a * step);
    const std::int64_t da = fa.by * step, db = fb.by * step, dc = fc.by * step;
    // The weights at x = 0 on row y (b0 + by * y), stepped exactly from row to row.
    std::int64_t ra = fa.b0 + fa.by * first_row, rb = fb.b0 + fb.by * first_row,
                 rc = fc.b0 + fc.by * first_row;
    for (std::int64_t y = first_row; y <= ymax;
         y += step, ba.next(), bb.next(), bc.next(), ra += da, rb += db, rc += dc) {
        std::int64_t lo = xmin;
        std::int64_t hi = xmax;
        ba.clip(lo, hi);
        bb.clip(lo, hi);
        bc.clip(lo, hi);
        lo = align(lo);
        if (lo > hi) {
            continue;
        }
        const std::int64_t last = step == 1 ? hi : lo + (hi - lo) / step * step; // last visited
        // The weights are integers below 2^53, so doubles hold and step them exactly.
        double wa = static_cast<double>(fa.a * lo + ra);
        double wb = static_cast<double>(fb.a * lo + rb);
        double wc = static_cast<double>(fc.a * lo + rc);
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
        const auto record = [&](std::int64_t x, double z) {
            const double err = std::abs(z - static_cast<double>(heights[x]));
            ++samples;
            total_error += err;
            if (err <= gate) {
                return false; // the common case: neither a new worst nor an error point
            }
            if (err > worst_error) {
                worst_error = err;
                worst_sample = static_cast<std::int64_t>(row) + x;
            }
            if (err > eps && ++error_points >= stop_at) {
                return true;
            }
            gate = std::min(worst_error, eps);
            return false;
        };
        // Visits the samples x = from, from + step, ..., to of the row, in increasing x.
        const auto visit = [&](std::int64_t from, std::int64_t to) {
            for (std::int64_t x = from; x <= to; x += step, wa += sa, wb += sb, wc += sc) {
                if (kMasked && valid[x] == 0) {
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
                if (record(x, z)) {
                    return true;
                }
            }
            return false;
        };
        if (visit(lo, last)) {
            return finish();
        }
    }
    return finish();
}

} // namespace

TriangleStats scan_triangle(const HeightGrid& grid,
                            double eps,
                            GridPoint a,
                            GridPoint b,
                            GridPoint c,
                            std::int64_t stop_at,
                            int stride) {
    // Masked and unmasked grids get separate loops: the validity test leaves the hot path.
    return grid.valid.empty() ? scan_rows<false>(grid, eps, a, b, c, stop_at, stride)
                              : scan_rows<true>(grid, eps, a, b, c, stop_at, stride);
}

} // namespace tb::core
