// The drawn tile against blocks of source pixels (see cell_check.hpp): every (triangle, cell)
// pair that meet, the cell's box clipped by the triangle, the linear difference evaluated at the
// clipped polygon's corners.
#include "tiler/mesh/cell_check.hpp"

#include <algorithm>
#include <cmath>

namespace tb::tiler {
namespace {

using Point = std::array<double, 2>;

// A box clipped by a triangle: at most 7 corners (4 + one per half-plane; room for more).
struct Polygon {
    std::array<Point, 16> p{};
    int n = 0;
};

// Keeps the part of `in` on the left of a -> b (scaled by `sign`, the triangle's winding),
// Sutherland-Hodgman; points within `slack` of the line count as inside (a pixel on a shared
// edge belongs to both triangles).
Polygon clip(const Polygon& in, const Point& a, const Point& b, double sign, double slack) {
    Polygon out;
    const auto side = [&](const Point& q) {
        return sign * ((b[0] - a[0]) * (q[1] - a[1]) - (b[1] - a[1]) * (q[0] - a[0]));
    };
    for (int k = 0; k < in.n; ++k) {
        const Point& p = in.p[static_cast<std::size_t>(k)];
        const Point& q = in.p[static_cast<std::size_t>((k + 1) % in.n)];
        const double sp = side(p), sq = side(q);
        if (sp >= -slack && out.n < 16) {
            out.p[static_cast<std::size_t>(out.n++)] = p;
        }
        if ((sp >= -slack) != (sq >= -slack) && out.n < 16) {
            const double t = sp / (sp - sq);
            out.p[static_cast<std::size_t>(out.n++)] = {p[0] + t * (q[0] - p[0]),
                                                        p[1] + t * (q[1] - p[1])};
        }
    }
    return out;
}

// Cells bucketed by their boxes on a uniform grid, so a triangle visits only the cells near it.
class CellBuckets {
public:
    explicit CellBuckets(const std::vector<CheckCell>& cells) {
        lo_ = {INFINITY, INFINITY};
        Point hi{-INFINITY, -INFINITY};
        for (const CheckCell& c : cells) {
            lo_ = {std::min(lo_[0], c.x0), std::min(lo_[1], c.y0)};
            hi = {std::max(hi[0], c.x1), std::max(hi[1], c.y1)};
        }
        const double span = std::max({hi[0] - lo_[0], hi[1] - lo_[1], 1e-9});
        const double across = std::max(1.0, std::sqrt(static_cast<double>(cells.size())) / 2);
        size_ = span / across;
        nx_ = index(hi[0], lo_[0]) + 1;
        ny_ = index(hi[1], lo_[1]) + 1;
        start_.assign(static_cast<std::size_t>(nx_) * ny_ + 1, 0);
        for_each_bucket(cells, [&](std::size_t b, std::uint32_t) { ++start_[b + 1]; });
        for (std::size_t b = 1; b < start_.size(); ++b) {
            start_[b] += start_[b - 1];
        }
        items_.resize(start_.back());
        std::vector<std::uint32_t> fill(start_.begin(), start_.end() - 1);
        for_each_bucket(cells, [&](std::size_t b, std::uint32_t k) { items_[fill[b]++] = k; });
    }

    // Calls f(cell index) for each cell in a bucket meeting the box (a cell may come twice).
    template <typename F> void near(double x0, double y0, double x1, double y1, F&& f) const {
        const int i0 = index(x0, lo_[0]), i1 = index(x1, lo_[0]);
        const int j0 = index(y0, lo_[1]), j1 = index(y1, lo_[1]);
        for (int j = std::max(j0, 0); j <= std::min(j1, ny_ - 1); ++j) {
            for (int i = std::max(i0, 0); i <= std::min(i1, nx_ - 1); ++i) {
                const std::size_t b = static_cast<std::size_t>(j) * nx_ + i;
                for (std::uint32_t o = start_[b]; o < start_[b + 1]; ++o) {
                    f(items_[o]);
                }
            }
        }
    }

private:
    int index(double v, double lo) const {
        return static_cast<int>(std::clamp(std::floor((v - lo) / size_), -1.0, 1e8));
    }
    template <typename F> void for_each_bucket(const std::vector<CheckCell>& cells, F&& f) const {
        for (std::uint32_t k = 0; k < cells.size(); ++k) {
            const CheckCell& c = cells[k];
            for (int j = index(c.y0, lo_[1]); j <= index(c.y1, lo_[1]); ++j) {
                for (int i = index(c.x0, lo_[0]); i <= index(c.x1, lo_[0]); ++i) {
                    f(static_cast<std::size_t>(j) * nx_ + i, k);
                }
            }
        }
    }

    Point lo_{};
    double size_ = 1;
    int nx_ = 1, ny_ = 1;
    std::vector<std::uint32_t> start_, items_;
};

} // namespace

CellsVerdict cells_error(const GridSurface& surface, const std::vector<CheckCell>& cells) {
    CellsVerdict verdict;
    if (cells.empty()) {
        return verdict;
    }
    const CellBuckets buckets(cells);
    std::vector<std::uint8_t> met(cells.size(), 0);
    const auto& v = surface.vertices;
    for (std::size_t t = 0; t + 2 < surface.triangles.size(); t += 3) {
        const auto& a = v[surface.triangles[t]];
        const auto& b = v[surface.triangles[t + 1]];
        const auto& c = v[surface.triangles[t + 2]];
        const double det = (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1]);
        if (det == 0) {
            continue; // collapsed: its neighbours cover the same points
        }
        // The triangle's plane: height = a + gx (x - ax) + gy (y - ay).
        const double gx = ((b[2] - a[2]) * (c[1] - a[1]) - (c[2] - a[2]) * (b[1] - a[1])) / det;
        const double gy = ((c[2] - a[2]) * (b[0] - a[0]) - (b[2] - a[2]) * (c[0] - a[0])) / det;
        const double sign = det > 0 ? 1.0 : -1.0;
        const double slack = 1e-9 * std::abs(det);
        const Point pa{a[0], a[1]}, pb{b[0], b[1]}, pc{c[0], c[1]};
        const double x0 = std::min({a[0], b[0], c[0]}), x1 = std::max({a[0], b[0], c[0]});
        const double y0 = std::min({a[1], b[1], c[1]}), y1 = std::max({a[1], b[1], c[1]});
        buckets.near(x0, y0, x1, y1, [&](std::uint32_t k) {
            const CheckCell& cell = cells[k];
            if (cell.x1 < x0 || cell.x0 > x1 || cell.y1 < y0 || cell.y0 > y1) {
                return;
            }
            Polygon box;
            box.n = 4;
            box.p = {Point{cell.x0, cell.y0},
                     {cell.x1, cell.y0},
                     {cell.x1, cell.y1},
                     {cell.x0, cell.y1}};
            Polygon part = clip(
                clip(clip(box, pa, pb, sign, slack), pb, pc, sign, slack), pc, pa, sign, slack);
            if (part.n == 0) {
                return;
            }
            met[k] = 1;
            for (int q = 0; q < part.n; ++q) {
                const Point& p = part.p[static_cast<std::size_t>(q)];
                const double drawn = a[2] + gx * (p[0] - a[0]) + gy * (p[1] - a[1]);
                verdict.error = std::max(verdict.error,
                                         std::abs(drawn - cell.reference(p[0], p[1])) + cell.half);
            }
        });
    }
    verdict.outside = static_cast<std::size_t>(std::count(met.begin(), met.end(), 0));
    return verdict;
}

} // namespace tb::tiler
