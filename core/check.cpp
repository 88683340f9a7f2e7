// The guarantee checks: check_mesh (exact tiling) and max_error (exact L-infinity error).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "core/error.hpp"
#include "core/memory.hpp"
#include "core/predicates.hpp"
#include "core/triangulate.hpp"
#include "core/two_threads.hpp"

namespace tb::core {
namespace {

[[noreturn]] void fail(const std::string& what) {
    throw Error("check_mesh: " + what);
}

std::string at(std::size_t t) {
    return "triangle " + std::to_string(t);
}

} // namespace

void check_mesh(const Mesh& mesh, int width, int height) {
    const std::size_t ne = mesh.triangles.size();
    if (ne % 3 != 0 || mesh.halfedges.size() != ne) {
        fail("triangles and halfedges sizes disagree");
    }
    if (mesh.z.size() != mesh.points.size()) {
        fail("z and points sizes disagree");
    }
    for (const GridPoint& p : mesh.points) {
        if (p.x < 0 || p.y < 0 || p.x >= width || p.y >= height) {
            fail("vertex off the grid at x=" + std::to_string(p.x) + " y=" + std::to_string(p.y));
        }
    }
    const auto on_boundary = [&](GridPoint a, GridPoint b) {
        return (a.x == 0 && b.x == 0) || (a.y == 0 && b.y == 0) ||
               (a.x == width - 1 && b.x == width - 1) || (a.y == height - 1 && b.y == height - 1);
    };
    std::int64_t doubled = 0;
    for (std::size_t e = 0; e < ne; ++e) {
        if (mesh.triangles[e] >= mesh.points.size()) {
            fail("half-edge " + std::to_string(e) + " starts at no vertex");
        }
    }
    for (std::size_t t = 0; t < ne / 3; ++t) {
        const GridPoint a = mesh.points[mesh.triangles[3 * t]];
        const GridPoint b = mesh.points[mesh.triangles[3 * t + 1]];
        const GridPoint c = mesh.points[mesh.triangles[3 * t + 2]];
        const std::int64_t area = orient2d(a, b, c);
        if (area <= 0) {
            fail(at(t) + (area == 0 ? " has zero area" : " is clockwise"));
        }
        doubled += area;
    }
    for (std::size_t e = 0; e < ne; ++e) {
        const Index ei = static_cast<Index>(e);
        const Index twin = mesh.halfedges[e];
        const Index from = mesh.triangles[e];
        const Index to = mesh.triangles[next_edge(ei)];
        if (twin == kNone) {
            if (!on_boundary(mesh.points[from], mesh.points[to])) {
                fail("border half-edge " + std::to_string(e) + " of " + at(e / 3) +
                     " is not on the grid boundary (T-junction or hole)");
            }
            continue;
        }
        if (twin >= ne || mesh.halfedges[twin] != ei) {
            fail("half-edge " + std::to_string(e) + " and its twin disagree");
        }
        if (mesh.triangles[twin] != to || mesh.triangles[next_edge(twin)] != from) {
            fail("half-edge " + std::to_string(e) + " and its twin join different vertices");
        }
    }
    const std::int64_t want = 2 * std::int64_t{width - 1} * (height - 1);
    if (doubled != want) {
        fail("triangles cover doubled area " + std::to_string(doubled) + ", expected " +
             std::to_string(want));
    }
}

namespace {

// One bit per sample, set when some triangle covers it.
class Coverage {
public:
    explicit Coverage(std::size_t samples) : bits_((samples + 63) / 64, 0), samples_(samples) {}
    // Marks samples [first, last] (last >= first).
    void mark(std::size_t first, std::size_t last) {
        TB_ASSERT(first <= last && last < samples_);
        const std::size_t w0 = first / 64, w1 = last / 64;
        const std::uint64_t head = ~std::uint64_t{0} << (first % 64);
        const std::uint64_t tail = ~std::uint64_t{0} >> (63 - last % 64);
        if (w0 == w1) {
            bits_[w0] |= head & tail;
            return;
        }
        bits_[w0] |= head;
        for (std::size_t k = w0 + 1; k < w1; ++k) {
            bits_[k] = ~std::uint64_t{0};
        }
        bits_[w1] |= tail;
    }
    // True when every sample with valid[i] != 0 (every sample when valid is empty) is marked.
    // Adds other's marks (the same number of samples).
    void merge(const Coverage& other) {
        for (std::size_t k = 0; k < bits_.size(); ++k) {
            bits_[k] |= other.bits_[k];
        }
    }
    bool covers(const std::vector<std::uint8_t>& valid) const {
        for (std::size_t k = 0; k < bits_.size(); ++k) {
            if (bits_[k] == ~std::uint64_t{0}) {
                continue;
            }
            const std::size_t end = std::min(samples_, 64 * k + 64);
            for (std::size_t i = 64 * k; i < end; ++i) {
                if ((bits_[k] >> (i % 64) & 1) == 0 && (valid.empty() || valid[i] != 0)) {
                    return false;
                }
            }
        }
        return true;
    }

private:
    LargeVector<std::uint64_t> bits_;
    std::size_t samples_;
};

// The largest error of the samples of triangles [from, to), each over its closed area; marks
// them in covered.
double judge_triangles(const Mesh& mesh,
                       const HeightGrid& grid,
                       std::size_t begin,
                       std::size_t end,
                       Coverage& covered) {
    const int w = grid.width;
    double worst = 0.0;
    for (std::size_t t = begin; t < end; ++t) {
        const Index ia = mesh.triangles[3 * t], ib = mesh.triangles[3 * t + 1],
                    ic = mesh.triangles[3 * t + 2];
        const GridPoint a = mesh.points[ia], b = mesh.points[ib], c = mesh.points[ic];
        const double za = mesh.z[ia], zb = mesh.z[ib], zc = mesh.z[ic];
        const double inv_area = inverse_area(a, b, c);
        const int y0 = std::min({a.y, b.y, c.y}), y1 = std::max({a.y, b.y, c.y});
        const int x0 = std::min({a.x, b.x, c.x}), x1 = std::max({a.x, b.x, c.x});
        const GridPoint from[3] = {b, c, a};
        const GridPoint to[3] = {c, a, b};
        for (int y = y0; y <= y1; ++y) {
            // The closed triangle's span on row y: orient2d(from, to, (x, y)) >= 0 per edge.
            std::int64_t lo = x0, hi = x1;
            for (int k = 0; k < 3; ++k) {
                const std::int64_t dx = std::int64_t{to[k].x} - from[k].x;
                const std::int64_t dy = std::int64_t{to[k].y} - from[k].y;
                const std::int64_t base = dx * (y - from[k].y) + dy * from[k].x; // - dy * x
                if (dy < 0) {
                    lo = std::max(lo, ceil_div(-base, -dy));
                } else if (dy > 0) {
                    hi = std::min(hi, floor_div(base, dy));
                } else if (base < 0) {
                    hi = lo - 1;
                }
            }
            if (lo > hi) {
                continue;
            }
            const GridPoint first{static_cast<std::int32_t>(lo), y};
            std::int64_t wa = orient2d(b, c, first);
            std::int64_t wb = orient2d(c, a, first);
            std::int64_t wc = orient2d(a, b, first);
            const std::int64_t sa = -(std::int64_t{c.y} - b.y), sb = -(std::int64_t{a.y} - c.y),
                               sc = -(std::int64_t{b.y} - a.y);
            const std::size_t row = static_cast<std::size_t>(y) * static_cast<std::size_t>(w);
            covered.mark(row + static_cast<std::size_t>(lo), row + static_cast<std::size_t>(hi));
            // Sample xx at weights (wa, wb, wc), anywhere in the closed triangle.
            const auto judge = [&](std::int64_t xx) {
                const GridPoint p{static_cast<std::int32_t>(xx), y};
                TB_ASSERT(wa >= 0 && wb >= 0 && wc >= 0);
                TB_ASSERT(wa == orient2d(b, c, p) && wc == orient2d(a, b, p));
                if (!grid.is_valid(p.x, y)) {
                    return;
                }
                const double z = interpolate(a, za, b, zb, c, zc, wa, wb, wc, inv_area, p);
                worst = std::max(worst, std::abs(z - static_cast<double>(grid.heights[row + p.x])));
            };
            // Off a horizontal edge's row only the span's two ends can lie on an edge (each
            // edge line crosses the row once, where its weight reaches 0, which bounds the
            // span): the samples between take interpolate()'s inside formula directly.
            const bool edge_row =
                (a.y == y && b.y == y) || (b.y == y && c.y == y) || (c.y == y && a.y == y);
            if (edge_row || hi - lo < 2) {
                for (std::int64_t xx = lo; xx <= hi; ++xx, wa += sa, wb += sb, wc += sc) {
                    judge(xx);
                }
                continue;
            }
            judge(lo);
            const float* heights = grid.heights.data() + row;
            const std::uint8_t* valid = grid.valid.empty() ? nullptr : grid.valid.data() + row;
            // The weights are integers below 2^53: doubles step them exactly, so each sample
            // gets the same inside formula, on the same values, as interpolate() would.
            const double fa = static_cast<double>(sa), fb = static_cast<double>(sb),
                         fc = static_cast<double>(sc);
            double da = static_cast<double>(wa + sa), db = static_cast<double>(wb + sb),
                   dc = static_cast<double>(wc + sc);
            double row_worst = 0.0;
            for (std::int64_t xx = lo + 1; xx < hi; ++xx, da += fa, db += fb, dc += fc) {
                TB_ASSERT(da > 0 && db > 0 && dc > 0);
                if (valid != nullptr && valid[xx] == 0) {
                    continue;
                }
                const double z = interpolate_inside(da, db, dc, za, zb, zc, inv_area);
                row_worst = std::max(row_worst, std::abs(z - static_cast<double>(heights[xx])));
            }
            worst = std::max(worst, row_worst);
            const std::int64_t steps = hi - lo;
            wa += steps * sa, wb += steps * sb, wc += steps * sc;
            judge(hi);
        }
    }
    return worst;
}

} // namespace

double max_error(const Mesh& mesh, const HeightGrid& grid, int threads) {
    // Every triangle is scanned over its closed area, so a sample on an edge is judged by every
    // triangle that touches it; a valid sample covered by none makes the error infinite. Two
    // threads judge a half of the triangles each, with a coverage each.
    const std::size_t samples = static_cast<std::size_t>(grid.width) * grid.height;
    const std::size_t n = mesh.triangle_count(), half = threads >= 2 ? n / 2 : n;
    Coverage covered(samples);
    double worst = 0.0, second_worst = 0.0;
    if (half == n) {
        worst = judge_triangles(mesh, grid, 0, n, covered);
    } else {
        Coverage second(samples);
        run_both(
            true,
            [&] { worst = judge_triangles(mesh, grid, 0, half, covered); },
            [&] { second_worst = judge_triangles(mesh, grid, half, n, second); });
        covered.merge(second);
    }
    worst = std::max(worst, second_worst);
    return covered.covers(grid.valid) ? worst : std::numeric_limits<double>::infinity();
}

double longest_edge(const Mesh& mesh) {
    std::int64_t best = 0;
    for (std::size_t e = 0; e < mesh.triangles.size(); ++e) {
        const Index next = static_cast<Index>(e % 3 == 2 ? e - 2 : e + 1);
        const GridPoint a = mesh.points[mesh.triangles[e]];
        const GridPoint b = mesh.points[mesh.triangles[next]];
        const std::int64_t dx = b.x - a.x, dy = b.y - a.y;
        best = std::max(best, dx * dx + dy * dy);
    }
    return std::sqrt(static_cast<double>(best));
}

} // namespace tb::core
