// §3.1 1-D optimal fits: optimal counts against brute force, chains inside the eps tunnel.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "core/breakpoints.hpp"
#include "core/triangulate.hpp"
#include "tests/core/brute_force.hpp"
#include "tests/core/terrains.hpp"

namespace {

// A random scan line of seed `seed`: 2 + up to `spread` samples of noise (a slope on odd seeds),
// every third seed with a validity mask, and an eps drawn after the samples. Non-dyadic eps keeps
// samples off the exact tunnel wall.
struct RandomLine {
    std::vector<float> z;
    std::vector<std::uint8_t> valid;
    double eps = 0;
};

RandomLine random_line(std::uint64_t seed, int spread) {
    terrain::Lcg r(seed);
    RandomLine line;
    const int n = 2 + static_cast<int>(r.next() * spread);
    const bool masked = seed % 3 == 0;
    for (int k = 0; k < n; ++k) {
        line.z.push_back(terrain::quantize(r.next() * 10.0 + (seed % 2 ? k * 1.7 : 0.0)));
        if (masked) {
            line.valid.push_back(r.next() < 0.7 ? 1 : 0);
        }
    }
    line.eps = 0.3 + 3.1 * r.next();
    return line;
}

} // namespace

TEST_CASE("the 1-D fit has the brute-force optimal count on random sequences (seeds 1-300)") {
    for (std::uint64_t seed = 1; seed <= 300; ++seed) {
        const auto [z, valid, eps] = random_line(seed, 12);
        const int n = static_cast<int>(z.size());
        const auto chain = tb::core::fit_breakpoints(z, valid, eps);
        INFO("seed=", seed, " n=", n, " eps=", eps);
        REQUIRE(chain.front() == 0);
        REQUIRE(chain.back() == n - 1);
        for (std::size_t s = 1; s < chain.size(); ++s) {
            CHECK(chain[s - 1] < chain[s]);
            CHECK(brute::fits(z, valid, eps, chain[s - 1], chain[s]));
        }
        CHECK(static_cast<int>(chain.size()) == brute::optimal_breakpoints(z, valid, eps));
    }
}

namespace {

// Fewest breakpoints as a shortest path over every segment brute::fits accepts (and no longer
// than max_step): the optimum brute::optimal_breakpoints enumerates, in O(n^3), so that long
// scan lines can be judged.
int shortest_chain(const std::vector<float>& z,
                   const std::vector<std::uint8_t>& valid,
                   double eps,
                   int max_step) {
    const int n = static_cast<int>(z.size());
    std::vector<int> best(static_cast<std::size_t>(n), n + 1);
    best[0] = 1;
    for (int j = 1; j < n; ++j) {
        for (int i = std::max(0, j - max_step); i < j; ++i) {
            if (best[static_cast<std::size_t>(i)] + 1 < best[static_cast<std::size_t>(j)] &&
                brute::fits(z, valid, eps, i, j)) {
                best[static_cast<std::size_t>(j)] = best[static_cast<std::size_t>(i)] + 1;
            }
        }
    }
    return best[static_cast<std::size_t>(n - 1)];
}

} // namespace

TEST_CASE("the 1-D fit is optimal on long scan lines at coarse eps (seeds 1-40)") {
    // Slow drifts with flat steps and rare spikes: eps tunnels run over tens to hundreds of
    // samples, and close anywhere along them.
    int longest = 0;
    for (std::uint64_t seed = 1; seed <= 40; ++seed) {
        terrain::Lcg r(seed);
        const int n = 40 + static_cast<int>(r.next() * 160);
        std::vector<float> z;
        std::vector<std::uint8_t> valid;
        const bool masked = seed % 3 == 0;
        double h = 0.0;
        double drift = r.next() - 0.5;
        for (int k = 0; k < n; ++k) {
            const double u = r.next();
            if (u < 0.05) {
                drift = r.next() - 0.5;
            } else if (u > 0.3) {
                h += drift + 0.4 * (r.next() - 0.5);
            }
            z.push_back(terrain::quantize(r.next() < 0.02 ? h + 40.0 * (r.next() - 0.5) : h));
            if (masked) {
                valid.push_back(r.next() < 0.8 ? 1 : 0);
            }
        }
        // Non-dyadic eps keeps samples off the exact tunnel wall.
        const double eps = 1.3 + 7.1 * r.next();
        const int max_step = seed % 4 == 0 ? 3 + static_cast<int>(r.next() * 40) : 0;
        const int reach = max_step > 0 ? max_step : n;
        const auto chain = tb::core::fit_breakpoints(z, valid, eps, max_step);
        INFO("seed=", seed, " n=", n, " eps=", eps, " max_step=", max_step);
        REQUIRE(chain.front() == 0);
        REQUIRE(chain.back() == n - 1);
        for (std::size_t s = 1; s < chain.size(); ++s) {
            CHECK(chain[s - 1] < chain[s]);
            CHECK(chain[s] - chain[s - 1] <= reach);
            CHECK(brute::fits(z, valid, eps, chain[s - 1], chain[s]));
            longest = std::max(longest, chain[s] - chain[s - 1]);
        }
        CHECK(static_cast<int>(chain.size()) == shortest_chain(z, valid, eps, reach));
    }
    // The lines did hold long tunnels.
    CHECK(longest >= 60);
}

TEST_CASE("the 1-D fit has the optimal count on hand-made cases") {
    using V = std::vector<float>;
    const std::vector<std::uint8_t> all;
    // A straight line: just the ends.
    CHECK(tb::core::fit_breakpoints(V{0, 1, 2, 3, 4, 5}, all, 0.1).size() == 2);
    // A tent: ends plus the apex.
    CHECK(tb::core::fit_breakpoints(V{0, 1, 2, 3, 2, 1, 0}, all, 0.1) == std::vector<int>{0, 3, 6});
    // The same tent within a wide tunnel: the apex is within eps of the flat chain.
    CHECK(tb::core::fit_breakpoints(V{0, 1, 2, 3, 2, 1, 0}, all, 3.5).size() == 2);
    // Two samples: always both.
    CHECK(tb::core::fit_breakpoints(V{5, -5}, all, 1.0) == std::vector<int>{0, 1});
    // An invalid spike constrains nothing.
    CHECK(
        tb::core::fit_breakpoints(V{0, 0, 90, 0, 0}, std::vector<std::uint8_t>{1, 1, 0, 1, 1}, 0.5)
            .size() == 2);
}

TEST_CASE("the greedy chain stays in the eps tunnel with no fewer breakpoints than the optimum "
          "(seeds 1-300)") {
    for (std::uint64_t seed = 1; seed <= 300; ++seed) {
        // Off the tunnel wall, the greedy chain's cross-multiplied test and the exact one agree.
        const auto [z, valid, eps] = random_line(seed, 40);
        const int n = static_cast<int>(z.size());
        const int max_step = seed % 4 == 0 ? 3 : 0;
        const auto chain = tb::core::greedy_breakpoints(z, valid, eps, max_step);
        INFO("seed=", seed, " n=", n, " eps=", eps, " max_step=", max_step);
        REQUIRE(chain.front() == 0);
        REQUIRE(chain.back() == n - 1);
        for (std::size_t s = 1; s < chain.size(); ++s) {
            CHECK(chain[s - 1] < chain[s]);
            CHECK((max_step == 0 || chain[s] - chain[s - 1] <= max_step));
            CHECK(brute::fits(z, valid, eps, chain[s - 1], chain[s]));
        }
        CHECK(chain.size() >= tb::core::fit_breakpoints(z, valid, eps, max_step).size());
    }
}

TEST_CASE("the greedy chain takes the longest hop from each breakpoint on hand-made cases") {
    using V = std::vector<float>;
    const std::vector<std::uint8_t> all;
    CHECK(tb::core::greedy_breakpoints(V{0, 1, 2, 3, 4, 5}, all, 0.1) == std::vector<int>{0, 5});
    CHECK(tb::core::greedy_breakpoints(V{0, 1, 2, 3, 2, 1, 0}, all, 0.1) ==
          std::vector<int>{0, 3, 6});
    CHECK(tb::core::greedy_breakpoints(V{5, -5}, all, 1.0) == std::vector<int>{0, 1});
    CHECK(tb::core::greedy_breakpoints(V{0, 0, 90, 0, 0},
                                       std::vector<std::uint8_t>{1, 1, 0, 1, 1},
                                       0.5) == std::vector<int>{0, 4});
    // With max_step 2 a straight line still needs a breakpoint every 2 samples.
    CHECK(tb::core::greedy_breakpoints(V{0, 1, 2, 3, 4, 5}, all, 0.1, 2) ==
          std::vector<int>{0, 2, 4, 5});
    // Where the farthest first hop is not optimal: never fewer than the optimum.
    const V z{0, 0, 0, 0, 3, 6, 3, 0, 0, 0};
    for (double eps : {0.4, 0.9, 1.3, 2.2}) {
        INFO("eps=", eps);
        CHECK(tb::core::greedy_breakpoints(z, all, eps).size() >=
              tb::core::fit_breakpoints(z, all, eps).size());
    }
}

TEST_CASE("a fit where the farthest first hop is not optimal still finds the optimum") {
    // Greedy longest reach from 0 lands on a sample from which the rest needs more hops; the
    // shortest-hop search is exact. Checked against brute force on the spot.
    const std::vector<float> z{0, 0, 0, 0, 3, 6, 3, 0, 0, 0};
    const std::vector<std::uint8_t> all;
    for (double eps : {0.4, 0.9, 1.3, 2.2}) {
        INFO("eps=", eps);
        CHECK(static_cast<int>(tb::core::fit_breakpoints(z, all, eps).size()) ==
              brute::optimal_breakpoints(z, all, eps));
    }
}

TEST_CASE("anchor points on each border are exactly that border's optimal fit (seed 2)") {
    const auto g = terrain::noise(40, 30, 2, 30.0, 2.0);
    const auto pts = tb::core::anchor_points(g, 1.0);
    auto has = [&](int x, int y) {
        return std::find(pts.begin(), pts.end(), tb::core::GridPoint{x, y}) != pts.end();
    };
    CHECK(has(0, 0));
    CHECK(has(39, 0));
    CHECK(has(0, 29));
    CHECK(has(39, 29));
    // Regression: scan lines once added their end points to the other borders, which broke
    // the locked-border guarantee (a border sample 1.6 > eps 1.5 on a 60x50 noise grid).
    auto border = [&](int side) {
        std::vector<int> got;
        for (const auto& p : pts) {
            const bool on = side == 0   ? p.y == 0
                            : side == 1 ? p.y == 29
                            : side == 2 ? p.x == 0
                                        : p.x == 39;
            if (on) {
                got.push_back(side < 2 ? p.x : p.y);
            }
        }
        return got;
    };
    for (int side = 0; side < 4; ++side) {
        INFO("side=", side);
        CHECK(border(side) == tb::core::border_breakpoints(g, 1.0, side));
    }
}

namespace {

std::vector<float> column_of(const tb::core::HeightGrid& g, int x) {
    std::vector<float> z;
    for (int y = 0; y < g.height; ++y) {
        z.push_back(g.at(x, y));
    }
    return z;
}

std::vector<float> row_of(const tb::core::HeightGrid& g, int y) {
    std::vector<float> z;
    for (int x = 0; x < g.width; ++x) {
        z.push_back(g.at(x, y));
    }
    return z;
}

bool raster_before(tb::core::GridPoint a, tb::core::GridPoint b) {
    return a.y != b.y ? a.y < b.y : a.x < b.x;
}

// The anchors of the paper (§3.1), rebuilt from the 1-D fits: the four borders, the vertical
// scan lines through the horizontal border with fewer breakpoints (top on ties) and the
// horizontal ones through the vertical border with fewer (left on ties).
std::vector<tb::core::GridPoint> paper_anchors(const tb::core::HeightGrid& g, double eps) {
    using tb::core::border_breakpoints;
    const std::vector<std::uint8_t> all;
    const auto top = border_breakpoints(g, eps, 0), bottom = border_breakpoints(g, eps, 1);
    const auto left = border_breakpoints(g, eps, 2), right = border_breakpoints(g, eps, 3);
    std::vector<tb::core::GridPoint> pts;
    for (int x : top)
        pts.push_back({x, 0});
    for (int x : bottom)
        pts.push_back({x, g.height - 1});
    for (int y : left)
        pts.push_back({0, y});
    for (int y : right)
        pts.push_back({g.width - 1, y});
    const auto& cols = bottom.size() < top.size() ? bottom : top;
    for (std::size_t i = 1; i + 1 < cols.size(); ++i) {
        const auto ys = tb::core::fit_breakpoints(column_of(g, cols[i]), all, eps);
        for (std::size_t k = 1; k + 1 < ys.size(); ++k)
            pts.push_back({cols[i], ys[k]});
    }
    const auto& rows = right.size() < left.size() ? right : left;
    for (std::size_t i = 1; i + 1 < rows.size(); ++i) {
        const auto xs = tb::core::fit_breakpoints(row_of(g, rows[i]), all, eps);
        for (std::size_t k = 1; k + 1 < xs.size(); ++k)
            pts.push_back({xs[k], rows[i]});
    }
    std::sort(pts.begin(), pts.end(), raster_before);
    pts.erase(std::unique(pts.begin(), pts.end()), pts.end());
    return pts;
}

} // namespace

TEST_CASE("anchor points are the paper's when they are many, and denser scan lines add "
          "1-D optimal breakpoints when they are few") {
    const std::vector<std::uint8_t> all;
    // Fine eps on rough noise: the paper's anchors are well over 1% of the 30,000 samples.
    {
        const auto g = terrain::noise(200, 150, 3, 60.0, 4.0);
        const auto paper = paper_anchors(g, 0.5);
        REQUIRE(paper.size() > 300);
        CHECK(tb::core::anchor_points(g, 0.5) == paper);
    }
    // Coarse eps on smooth noise: few anchors, so more scan lines are fitted.
    {
        const auto g = terrain::noise(200, 150, 3, 60.0, 0.5);
        const double eps = 6.0;
        const auto paper = paper_anchors(g, eps);
        const auto pts = tb::core::anchor_points(g, eps);
        INFO("paper ", paper.size(), " anchors, got ", pts.size());
        REQUIRE(paper.size() < 300);
        CHECK(std::is_sorted(pts.begin(), pts.end(), raster_before));
        CHECK(std::includes(pts.begin(), pts.end(), paper.begin(), paper.end(), raster_before));
        CHECK(pts.size() > paper.size());
        // Every extra anchor is an interior breakpoint of its own column's or row's optimal fit,
        // and none is on a border (the borders stay exactly their fits).
        for (const auto& p : pts) {
            if (std::binary_search(paper.begin(), paper.end(), p, raster_before)) {
                continue;
            }
            INFO("x=", p.x, " y=", p.y);
            CHECK(p.x > 0);
            CHECK(p.y > 0);
            CHECK(p.x < g.width - 1);
            CHECK(p.y < g.height - 1);
            const auto ys = tb::core::fit_breakpoints(column_of(g, p.x), all, eps);
            const auto xs = tb::core::fit_breakpoints(row_of(g, p.y), all, eps);
            CHECK((std::binary_search(ys.begin(), ys.end(), p.y) ||
                   std::binary_search(xs.begin(), xs.end(), p.x)));
        }
    }
}
