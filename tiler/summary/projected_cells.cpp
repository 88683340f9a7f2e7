// Summary blocks as CheckCells on a grid that does not serve the scheme (projected_cells.hpp).
#include "tiler/summary/projected_cells.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <optional>

namespace tb::tiler {
namespace {

using Point = std::array<double, 2>; // tile grid (column, row)
using Probes = Point[kProbes][kProbes];

// Pixel columns i0..i1 and rows j0..j1 (inclusive).
struct PixelBox {
    std::int64_t i0 = 0, j0 = 0, i1 = -1, j1 = -1;
};

std::optional<PixelBox> pixels_under(const PixelPlace& place, const LonLatBox& tile, int level) {
    const LonLatBox f = place.footprint();
    const LonLatBox b{std::max(tile.west, f.west),
                      std::max(tile.south, f.south),
                      std::min(tile.east, f.east),
                      std::min(tile.north, f.north)};
    if (!(b.west <= b.east && b.south <= b.north)) {
        return std::nullopt;
    }
    constexpr int kSteps = 32;
    std::vector<double> xs, ys;
    for (int k = 0; k <= kSteps; ++k) {
        const double u = b.west + (b.east - b.west) * k / kSteps;
        const double v = b.south + (b.north - b.south) * k / kSteps;
        xs.insert(xs.end(), {u, u, b.west, b.east});
        ys.insert(ys.end(), {b.south, b.north, v, v});
    }
    place.to_pixels(xs, ys);
    const std::int64_t W = place.width(), H = place.height();
    PixelBox out{0, 0, W - 1, H - 1};
    const auto finite = [](double v) { return std::isfinite(v); };
    if (std::all_of(xs.begin(), xs.end(), finite) && std::all_of(ys.begin(), ys.end(), finite)) {
        const double margin = std::exp2(level) + 1;
        // Clamped as doubles first: a point far outside the raster may lie anywhere.
        const auto pixel = [](double v, std::int64_t n) {
            return static_cast<std::int64_t>(std::clamp(v, -1.0, static_cast<double>(n)));
        };
        const auto [x0, x1] = std::minmax_element(xs.begin(), xs.end());
        const auto [y0, y1] = std::minmax_element(ys.begin(), ys.end());
        out.i0 = std::max<std::int64_t>(0, pixel(std::floor(*x0 - margin), W));
        out.j0 = std::max<std::int64_t>(0, pixel(std::floor(*y0 - margin), H));
        out.i1 = std::min<std::int64_t>(W - 1, pixel(std::ceil(*x1 + margin), W));
        out.j1 = std::min<std::int64_t>(H - 1, pixel(std::ceil(*y1 + margin), H));
    }
    if (out.i0 > out.i1 || out.j0 > out.j1) {
        return std::nullopt;
    }
    return out;
}

// The pixel-edge coordinates of blocks first..last of `level` along an axis of n pixels: each
// block's first edge and its quarters, then the last block's far edge (kProbes - 1 per block,
// plus one).
std::vector<double> block_edges(std::int64_t first, std::int64_t last, int level, std::int64_t n) {
    std::vector<double> out;
    for (std::int64_t b = first; b <= last; ++b) {
        const double s0 = static_cast<double>(b << level) - 0.5;
        const double s4 = static_cast<double>(std::min((b + 1) << level, n)) - 0.5;
        for (int q = 0; q < kProbes - 1; ++q) {
            out.push_back(s0 + (s4 - s0) * q / (kProbes - 1));
        }
        if (b == last) {
            out.push_back(s4);
        }
    }
    return out;
}

// A block no affine map stands for: the whole tile, flat, spanning every height of its pixels.
CheckCell flat_cell(const DemSummary& summary,
                    const SummaryBlock& b,
                    int level,
                    std::int64_t bx,
                    std::int64_t by,
                    const TileRaster& raster) {
    double lo = INFINITY, hi = -INFINITY;
    for (const double i : {double(bx << level), double(summary.last_column(level, bx))}) {
        for (const double j : {double(by << level), double(summary.last_row(level, by))}) {
            const double p = DemSummary::plane(b, level, bx, by, i, j);
            lo = std::min(lo, p + b.low), hi = std::max(hi, p + b.high);
        }
    }
    CheckCell c;
    c.x1 = raster.grid.width - 1, c.y1 = raster.grid.height - 1;
    c.height = (lo + hi) / 2;
    c.half = (hi - lo) / 2 + 1e-6;
    return c;
}

// The cell of a block whose probes land at p[v][u] of the tile grid (u along columns, v along
// rows; 0 .. kProbes - 1 from its first edge to its far edge in equal steps), with s0 and s2 its
// first and far pixel edges along columns, t0 and t2 along rows. False when it lies outside the
// tile.
bool block_cell(const Probes& p,
                const DemSummary& summary,
                double s0,
                double s2,
                double t0,
                double t2,
                const SummaryBlock& b,
                int level,
                std::int64_t bx,
                std::int64_t by,
                const TileRaster& raster,
                CheckCell& c) {
    constexpr int e = kProbes - 1;
    const Point o = p[0][0];
    const Point U{p[0][e][0] - o[0], p[0][e][1] - o[1]}, V{p[e][0][0] - o[0], p[e][0][1] - o[1]};
    // A(σ, τ) = o + σ U + τ V; the stray T - A: the sum over the six points of the half-block
    // grid (a quadratic's bound), or the largest over every probe (a cubic's), with margins.
    double sum[2] = {0, 0}, most[2] = {0, 0};
    for (int v = 0; v <= e; ++v) {
        for (int u = 0; u <= e; ++u) {
            for (int a = 0; a < 2; ++a) {
                const double d = std::abs(p[v][u][a] - (o[a] + (U[a] * u + V[a] * v) / e));
                most[a] = std::max(most[a], d);
                const bool half_grid = u % 2 == 0 && v % 2 == 0;
                sum[a] += half_grid ? d : 0.0; // the three corners A passes through add 0
            }
        }
    }
    double stray[2];
    for (int a = 0; a < 2; ++a) {
        stray[a] = std::max(sum[a] * kStrayMargin, most[a] * kProbeMargin) + 1e-9;
    }
    const double xs[4] = {o[0], o[0] + U[0], o[0] + V[0], o[0] + U[0] + V[0]};
    const double ys[4] = {o[1], o[1] + U[1], o[1] + V[1], o[1] + U[1] + V[1]};
    c.x0 = std::max(0.0, *std::min_element(xs, xs + 4) - stray[0]);
    c.x1 = std::min(raster.grid.width - 1.0, *std::max_element(xs, xs + 4) + stray[0]);
    c.y0 = std::max(0.0, *std::min_element(ys, ys + 4) - stray[1]);
    c.y1 = std::min(raster.grid.height - 1.0, *std::max_element(ys, ys + 4) + stray[1]);
    if (!(c.x0 <= c.x1 && c.y0 <= c.y1)) {
        return false;
    }
    // Grid units per pixel (columns of M), and its inverse: pixel offsets per grid offset.
    const double m00 = U[0] / (s2 - s0), m10 = U[1] / (s2 - s0);
    const double m01 = V[0] / (t2 - t0), m11 = V[1] / (t2 - t0);
    const double det = m00 * m11 - m01 * m10;
    const double i00 = m11 / det, i01 = -m01 / det, i10 = -m10 / det, i11 = m00 / det;
    const double pc = b.per_column, pr = b.per_row;
    c.per_column = pc * i00 + pr * i10;
    c.per_row = pc * i01 + pr * i11;
    const double i = s0 + i00 * (c.x0 - o[0]) + i01 * (c.y0 - o[1]);
    const double j = t0 + i10 * (c.x0 - o[0]) + i11 * (c.y0 - o[1]);
    c.height =
        DemSummary::plane(b, level, bx, by, i, j) + (static_cast<double>(b.low) + b.high) / 2;
    c.half = (static_cast<double>(b.high) - b.low) / 2 + std::abs(c.per_column) * stray[0] +
             std::abs(c.per_row) * stray[1] + 1e-6;
    if (!(std::isfinite(c.height) && std::isfinite(c.half) && std::isfinite(c.per_column) &&
          std::isfinite(c.per_row))) {
        c = flat_cell(summary, b, level, bx, by, raster); // a block folded flat (det 0)
    }
    return true;
}

} // namespace

std::vector<CheckCell> projected_cells(const DemSummary& summary,
                                       const PixelPlace& place,
                                       const TileRaster& raster,
                                       int level) {
    std::vector<CheckCell> cells;
    const std::optional<PixelBox> under = pixels_under(place, raster.bounds, level);
    if (!under) {
        return cells;
    }
    const std::int64_t bx0 = under->i0 >> level, bx1 = under->i1 >> level;
    const std::int64_t by0 = under->j0 >> level, by1 = under->j1 >> level;
    constexpr std::size_t kStep = kProbes - 1;
    const std::vector<double> ss = block_edges(bx0, bx1, level, place.width());
    const std::vector<double> ts = block_edges(by0, by1, level, place.height());
    std::vector<double> xs, ys;
    xs.reserve(ss.size() * ts.size());
    ys.reserve(ss.size() * ts.size());
    for (const double t : ts) {
        for (const double s : ss) {
            xs.push_back(s), ys.push_back(t);
        }
    }
    place.to_lonlat(xs, ys);
    std::vector<Point> grid(xs.size());
    for (std::size_t k = 0; k < xs.size(); ++k) {
        lonlat_to_grid(raster, {xs[k], ys[k]}, grid[k][0], grid[k][1]);
    }
    for (std::int64_t by = by0; by <= by1; ++by) {
        for (std::int64_t bx = bx0; bx <= bx1; ++bx) {
            const SummaryBlock* b = summary.block(level, bx, by);
            if (b == nullptr || b->empty()) {
                continue;
            }
            const auto a = static_cast<std::size_t>(bx - bx0) * kStep;
            const auto r = static_cast<std::size_t>(by - by0) * kStep;
            Probes p;
            bool finite = true;
            for (std::size_t v = 0; v <= kStep; ++v) {
                for (std::size_t u = 0; u <= kStep; ++u) {
                    p[v][u] = grid[(r + v) * ss.size() + a + u];
                    finite = finite && std::isfinite(p[v][u][0]) && std::isfinite(p[v][u][1]);
                }
            }
            CheckCell c;
            if (!finite) {
                cells.push_back(flat_cell(summary, *b, level, bx, by, raster));
            } else if (block_cell(p,
                                  summary,
                                  ss[a],
                                  ss[a + kStep],
                                  ts[r],
                                  ts[r + kStep],
                                  *b,
                                  level,
                                  bx,
                                  by,
                                  raster,
                                  c)) {
                cells.push_back(c);
            }
        }
    }
    return cells;
}

} // namespace tb::tiler
