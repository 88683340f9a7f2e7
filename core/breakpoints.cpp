// Lu & Yun §3.1 "Initial Triangulation": the optimal PL curve fit (OPLA) of a scan line by a
// shortest-hop search over the samples, and the collection of the anchor points.
#include "core/breakpoints.hpp"

#include <algorithm>
#include <cmath>
#include <iterator>
#include <limits>

#include "core/error.hpp"
#include "core/predicates.hpp"
#include "core/radix_sort.hpp"
#include "core/triangulate.hpp"
#include "core/two_threads.hpp"

namespace tb::core {
namespace {

// The scan lines through both opposite borders' breakpoints, not only the sparser border's,
// are fitted when the anchors stay within this share of the samples. Every anchor is a vertex
// the merge agent later tries to remove, so the budget bounds the extra work. At coarse eps,
// where the paper's lines give few anchors, the denser start ends with 2-6% fewer triangles for
// 0-7% more time (bench/mesh_bench.sh: whitemtn-1025 eps 40, fuji-513 eps 50, synth-1025 eps
// 10, andes-1025 eps 160); at fine eps the extra lines would cost 15-30% more time for 2%
// fewer triangles, and the paper's lines alone are over the budget. (Denser still, halfway
// between the lines, gave 2-5% fewer again for 20-40% more time: not taken.)
constexpr double kAnchorBudget = 0.01;

bool is_valid(std::span<const std::uint8_t> valid, int k) {
    return valid.empty() || valid[static_cast<std::size_t>(k)] != 0;
}

// Worst valid sample strictly between i and j, and its error against the segment.
int worst_between(
    std::span<const float> z, std::span<const std::uint8_t> valid, int i, int j, double& worst) {
    worst = -1.0;
    int at = -1;
    for (int k = i + 1; k < j; ++k) {
        if (!is_valid(valid, k)) {
            continue;
        }
        const double e = std::abs(
            lerp_steps(
                z[static_cast<std::size_t>(i)], z[static_cast<std::size_t>(j)], k - i, j - i) -
            static_cast<double>(z[static_cast<std::size_t>(k)]));
        if (e > worst) {
            worst = e;
            at = k;
        }
    }
    return at;
}

// Appends the breakpoints of [i, j] after i (excluding i), splitting at the worst sample until
// every segment passes the exact test. Only reached when the slope tunnel and the exact edge
// interpolation disagree in the last bit.
void append_verified(std::span<const float> z,
                     std::span<const std::uint8_t> valid,
                     double eps,
                     int i,
                     int j,
                     std::vector<int>& out) {
    double worst = 0.0;
    const int k = worst_between(z, valid, i, j, worst);
    if (k < 0 || worst <= eps) {
        out.push_back(j);
        return;
    }
    append_verified(z, valid, eps, i, k, out);
    append_verified(z, valid, eps, k, j, out);
}

} // namespace

bool segment_fits(
    std::span<const float> z, std::span<const std::uint8_t> valid, double eps, int i, int j) {
    double worst = 0.0;
    const int k = worst_between(z, valid, i, j, worst);
    return k < 0 || worst <= eps;
}

int max_step_for(double max_edge) {
    if (!(max_edge > 0.0)) {
        return 0;
    }
    return static_cast<int>(std::clamp(std::floor(max_edge), 1.0, 2147483647.0));
}

std::vector<int> fit_breakpoints(std::span<const float> z,
                                 std::span<const std::uint8_t> valid,
                                 double eps,
                                 int max_step) {
    const int n = static_cast<int>(z.size());
    TB_ASSERT(n >= 2);
    TB_ASSERT(max_step >= 0);
    // The longest hop allowed; a hop of one sample always is, so n - 1 stays reachable.
    const int reach = max_step > 0 ? max_step : n;
    TB_ASSERT(valid.empty() || valid.size() == z.size());
    TB_ASSERT(eps > 0.0);
    // Shortest hops from 0: a hop i -> j is allowed when the segment stays within the eps
    // tunnel of every valid sample between, i.e. its slope lies in the intersection of the
    // slope windows [(z_k - eps - z_i) / (k - i), (z_k + eps - z_i) / (k - i)].
    constexpr int kUnreached = std::numeric_limits<int>::max();
    std::vector<int> hops(static_cast<std::size_t>(n), kUnreached);
    std::vector<int> from(static_cast<std::size_t>(n), -1);
    hops[0] = 0;
    // The divisions bound this loop. A wall candidate depends on j alone, not on the walls, so
    // the candidates are computed a block of samples ahead, where the compiler (-O3) packs them
    // two to a division instruction; each lane is the same correctly rounded division as a
    // scalar one, so the walls (and every tie against them) do not depend on the blocking. The
    // slope is divided only when the hop would improve hops[j].
    constexpr int kBlock = 8;
    double lo_cand[kBlock];
    double hi_cand[kBlock];
    for (int i = 0; i < n - 1; ++i) {
        // Hop counts only grow along the scan, so every i is final when reached here.
        const int next_hops = hops[static_cast<std::size_t>(i)] + 1;
        const double zi = z[static_cast<std::size_t>(i)];
        double lo = -std::numeric_limits<double>::infinity();
        double hi = std::numeric_limits<double>::infinity();
        const int last = static_cast<int>(std::min<std::int64_t>(std::int64_t{i} + reach, n - 1));
        bool open = true;
        for (int first = i + 1; open && first <= last; first += kBlock) {
            const int count = std::min(kBlock, last - first + 1);
            for (int k = 0; k < count; ++k) {
                const double zj = z[static_cast<std::size_t>(first + k)];
                const double run = first + k - i;
                lo_cand[k] = (zj - eps - zi) / run;
                hi_cand[k] = (zj + eps - zi) / run;
            }
            for (int k = 0; k < count; ++k) {
                const int j = first + k;
                if (next_hops < hops[static_cast<std::size_t>(j)]) {
                    const double slope =
                        (static_cast<double>(z[static_cast<std::size_t>(j)]) - zi) / (j - i);
                    if (slope >= lo && slope <= hi) {
                        hops[static_cast<std::size_t>(j)] = next_hops;
                        from[static_cast<std::size_t>(j)] = i;
                    }
                }
                if (is_valid(valid, j)) {
                    lo = std::max(lo, lo_cand[k]);
                    hi = std::min(hi, hi_cand[k]);
                    if (lo > hi) {
                        open = false;
                        break;
                    }
                }
            }
        }
    }
    std::vector<int> chain;
    for (int v = n - 1; v >= 0; v = from[static_cast<std::size_t>(v)]) {
        chain.push_back(v);
        if (v == 0) {
            break;
        }
    }
    std::reverse(chain.begin(), chain.end());
    TB_ASSERT(chain.front() == 0 && chain.back() == n - 1);
    std::vector<int> out{0};
    for (std::size_t s = 1; s < chain.size(); ++s) {
        append_verified(z, valid, eps, chain[s - 1], chain[s], out);
    }
    return out;
}

std::vector<int> greedy_breakpoints(std::span<const float> z,
                                    std::span<const std::uint8_t> valid,
                                    double eps,
                                    int max_step) {
    const int n = static_cast<int>(z.size());
    TB_ASSERT(n >= 2 && max_step >= 0 && eps > 0.0);
    TB_ASSERT(valid.empty() || valid.size() == z.size());
    const int reach = max_step > 0 ? max_step : n;
    std::vector<int> out{0};
    for (int i = 0; i < n - 1;) {
        const double zi = z[static_cast<std::size_t>(i)];
        const int last = static_cast<int>(std::min<std::int64_t>(std::int64_t{i} + reach, n - 1));
        // The tunnel's slope window [lo_num / lo_run, hi_num / hi_run] over the valid samples
        // passed so far (runs > 0); open while lo <= hi.
        double lo_num = -1.0, lo_run = 0.0, hi_num = 1.0, hi_run = 0.0;
        int best = i + 1;
        for (int j = i + 1; j <= last; ++j) {
            const double run = j - i;
            const double rise = static_cast<double>(z[static_cast<std::size_t>(j)]) - zi;
            // slope = rise / run, tested against the window of the samples strictly between.
            if (rise * lo_run >= lo_num * run && rise * hi_run <= hi_num * run) {
                best = j;
            }
            if (is_valid(valid, j)) {
                if ((rise - eps) * lo_run > lo_num * run) {
                    lo_num = rise - eps, lo_run = run;
                }
                if ((rise + eps) * hi_run < hi_num * run) {
                    hi_num = rise + eps, hi_run = run;
                }
                if (lo_num * hi_run > hi_num * lo_run) {
                    break;
                }
            }
        }
        out.push_back(best);
        i = best;
    }
    return out;
}

std::vector<int> border_breakpoints(const HeightGrid& grid, double eps, int side, int max_step) {
    const int w = grid.width;
    const int h = grid.height;
    const bool row = side < 2;
    const int n = row ? w : h;
    std::vector<float> z(static_cast<std::size_t>(n));
    std::vector<std::uint8_t> valid;
    if (!grid.valid.empty()) {
        valid.resize(static_cast<std::size_t>(n));
    }
    for (int k = 0; k < n; ++k) {
        const int x = row ? k : (side == 2 ? 0 : w - 1);
        const int y = row ? (side == 0 ? 0 : h - 1) : k;
        z[static_cast<std::size_t>(k)] = grid.at(x, y);
        if (!valid.empty()) {
            valid[static_cast<std::size_t>(k)] = grid.is_valid(x, y) ? 1 : 0;
        }
    }
    return fit_breakpoints(z, valid, eps, max_step);
}

namespace {

// The fit of a scan line: fit_breakpoints, or greedy_breakpoints when greedy.
std::vector<int> line_fit(std::span<const float> z,
                          std::span<const std::uint8_t> valid,
                          double eps,
                          int max_step,
                          bool greedy) {
    return greedy ? greedy_breakpoints(z, valid, eps, max_step)
                  : fit_breakpoints(z, valid, eps, max_step);
}

std::vector<int>
column_breakpoints(const HeightGrid& grid, double eps, int x, int max_step, bool greedy) {
    std::vector<float> z(static_cast<std::size_t>(grid.height));
    std::vector<std::uint8_t> valid;
    if (!grid.valid.empty()) {
        valid.resize(z.size());
    }
    for (int y = 0; y < grid.height; ++y) {
        z[static_cast<std::size_t>(y)] = grid.at(x, y);
        if (!valid.empty()) {
            valid[static_cast<std::size_t>(y)] = grid.is_valid(x, y) ? 1 : 0;
        }
    }
    return line_fit(z, valid, eps, max_step, greedy);
}

std::vector<int>
row_breakpoints(const HeightGrid& grid, double eps, int y, int max_step, bool greedy) {
    const auto first = grid.heights.begin() + static_cast<std::ptrdiff_t>(y) * grid.width;
    std::span<const float> z(&*first, static_cast<std::size_t>(grid.width));
    std::span<const std::uint8_t> valid;
    if (!grid.valid.empty()) {
        valid = std::span<const std::uint8_t>(grid.valid.data() +
                                                  static_cast<std::size_t>(y) * grid.width,
                                              static_cast<std::size_t>(grid.width));
    }
    return line_fit(z, valid, eps, max_step, greedy);
}

// The interior breakpoints of scan lines (column x for {true, x}, row y for {false, y}) appended
// to pts (greedy: greedy_breakpoints' chains); with threads = 2 the lines' two halves are fitted
// on two threads. Only a scan line's
// interior breakpoints are anchors: its ends lie on the other two borders, whose vertices are
// exactly their own fits.
void add_lines(const HeightGrid& grid,
               double eps,
               int cap,
               bool greedy,
               const std::vector<std::pair<bool, int>>& lines,
               int threads,
               std::vector<GridPoint>& pts) {
    const auto fit = [&](std::size_t from, std::size_t to, std::vector<GridPoint>& out) {
        for (std::size_t i = from; i < to; ++i) {
            const auto [column, at] = lines[i];
            const auto cuts = column ? column_breakpoints(grid, eps, at, cap, greedy)
                                     : row_breakpoints(grid, eps, at, cap, greedy);
            for (std::size_t k = 1; k + 1 < cuts.size(); ++k) {
                out.push_back(column ? GridPoint{at, cuts[k]} : GridPoint{cuts[k], at});
            }
        }
    };
    const std::size_t half = lines.size() / 2;
    std::vector<GridPoint> second;
    run_both(
        threads >= 2, [&] { fit(0, half, pts); }, [&] { fit(half, lines.size(), second); });
    pts.insert(pts.end(), second.begin(), second.end());
}

} // namespace

std::vector<GridPoint>
anchor_points(const HeightGrid& grid, double eps, int max_step, bool greedy_lines, int threads) {
    TB_ASSERT(max_step >= 0);
    const int w = grid.width;
    const int h = grid.height;
    std::vector<GridPoint> pts;
    const auto top = border_breakpoints(grid, eps, 0, max_step);
    const auto bottom = border_breakpoints(grid, eps, 1, max_step);
    const auto left = border_breakpoints(grid, eps, 2, max_step);
    const auto right = border_breakpoints(grid, eps, 3, max_step);
    for (int x : top) {
        pts.push_back({x, 0});
    }
    for (int x : bottom) {
        pts.push_back({x, h - 1});
    }
    for (int y : left) {
        pts.push_back({0, y});
    }
    for (int y : right) {
        pts.push_back({w - 1, y});
    }
    // The paper's scan lines: vertical ones through the breakpoints of the horizontal border
    // with fewer of them (top on ties), horizontal ones through those of the vertical border
    // with fewer (left on ties).
    const std::vector<int>& cols = bottom.size() < top.size() ? bottom : top;
    const std::vector<int>& rows = right.size() < left.size() ? right : left;
    std::vector<std::pair<bool, int>> lines;
    for (std::size_t i = 1; i + 1 < cols.size(); ++i) {
        lines.push_back({true, cols[i]});
    }
    for (std::size_t i = 1; i + 1 < rows.size(); ++i) {
        lines.push_back({false, rows[i]});
    }
    add_lines(grid, eps, max_step, greedy_lines, lines, threads, pts);
    // The scan lines through the other two borders' breakpoints too, when the anchors stay
    // few (see kAnchorBudget). Judged by a forecast (each new line has as many interior
    // breakpoints as the two borders parallel to it have on average), so no line is fitted to
    // be thrown away; the forecast can be wrong either way (a rugged interior between flat
    // borders), so the budget steers the cost, it does not bound the count.
    std::vector<int> all_cols, all_rows;
    std::set_union(
        top.begin(), top.end(), bottom.begin(), bottom.end(), std::back_inserter(all_cols));
    std::set_union(
        left.begin(), left.end(), right.begin(), right.end(), std::back_inserter(all_rows));
    const double per_column =
        std::max(0.0, static_cast<double>(left.size() + right.size()) / 2.0 - 2.0);
    const double per_row =
        std::max(0.0, static_cast<double>(top.size() + bottom.size()) / 2.0 - 2.0);
    const double forecast = static_cast<double>(pts.size()) +
                            static_cast<double>(all_cols.size() - cols.size()) * per_column +
                            static_cast<double>(all_rows.size() - rows.size()) * per_row;
    if (forecast <= kAnchorBudget * static_cast<double>(w) * static_cast<double>(h)) {
        lines.clear();
        for (std::size_t i = 1; i + 1 < all_cols.size(); ++i) {
            if (!std::binary_search(cols.begin(), cols.end(), all_cols[i])) {
                lines.push_back({true, all_cols[i]});
            }
        }
        for (std::size_t i = 1; i + 1 < all_rows.size(); ++i) {
            if (!std::binary_search(rows.begin(), rows.end(), all_rows[i])) {
                lines.push_back({false, all_rows[i]});
            }
        }
        add_lines(grid, eps, max_step, greedy_lines, lines, threads, pts);
    }
    // Raster order: by y * w + x, below 2^40.
    radix_sort(pts, [w](GridPoint p) {
        return static_cast<std::uint64_t>(p.y) * static_cast<std::uint64_t>(w) +
               static_cast<std::uint64_t>(p.x);
    });
    pts.erase(std::unique(pts.begin(), pts.end()), pts.end());
    return pts;
}

} // namespace tb::core
