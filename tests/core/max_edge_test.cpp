// TriangulateOptions::max_edge: every edge within the bound, on top of the L-infinity bound and
// the exact tiling; 1-D fits with a longest step against brute force; shared borders.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "core/breakpoints.hpp"
#include "core/error.hpp"
#include "core/triangulate.hpp"
#include "tests/core/brute_force.hpp"
#include "tests/core/linf_oracle.hpp"
#include "tests/core/terrains.hpp"

namespace {

using tb::core::HeightGrid;
using tb::core::Mesh;
using tb::core::TriangulateOptions;

// Independent of core's longest_edge: squared lengths from the triangle corners.
std::int64_t longest2(const Mesh& m) {
    std::int64_t best = 0;
    for (std::size_t t = 0; t < m.triangles.size() / 3; ++t) {
        for (std::size_t k = 0; k < 3; ++k) {
            const auto a = m.points[m.triangles[3 * t + k]];
            const auto b = m.points[m.triangles[3 * t + (k + 1) % 3]];
            const std::int64_t dx = b.x - a.x, dy = b.y - a.y;
            best = std::max(best, dx * dx + dy * dy);
        }
    }
    return best;
}

void check_all(const HeightGrid& g, double eps, bool lock, double max_edge) {
    const Mesh m = tb::core::triangulate(g, TriangulateOptions{eps, lock, max_edge});
    const oracle::Verdict v = oracle::judge(m, g, eps);
    CHECK(v.problem == "");
    CHECK(v.over_eps == 0);
    CHECK(static_cast<double>(longest2(m)) <= max_edge * max_edge);
    CHECK(tb::core::longest_edge(m) <= max_edge);
    CHECK_NOTHROW(tb::core::check_mesh(m, g.width, g.height));
}

} // namespace

TEST_CASE("the 1-D fit with a longest step has the brute-force optimal count (seeds 1-200)") {
    for (std::uint64_t seed = 1; seed <= 200; ++seed) {
        terrain::Lcg r(seed);
        const int n = 2 + static_cast<int>(r.next() * 12);
        std::vector<float> z;
        for (int k = 0; k < n; ++k) {
            z.push_back(terrain::quantize(seed % 4 == 0 ? 3.0 : r.next() * 6.0));
        }
        const double eps = 0.3 + 3.1 * r.next();
        const int max_step = 1 + static_cast<int>(r.next() * 5);
        INFO("seed=", seed, " n=", n, " eps=", eps, " max_step=", max_step);
        const auto chain = tb::core::fit_breakpoints(z, {}, eps, max_step);
        CHECK(static_cast<int>(chain.size()) == brute::optimal_breakpoints(z, {}, eps, max_step));
        for (std::size_t s = 1; s < chain.size(); ++s) {
            CHECK(chain[s] - chain[s - 1] <= max_step);
            CHECK(brute::fits(z, {}, eps, chain[s - 1], chain[s]));
        }
    }
}

TEST_CASE("max_edge 0 leaves the 1-D fit and the mesh exactly as without the option") {
    const HeightGrid g = terrain::noise(65, 49, 7, 60.0, 2.0);
    const Mesh a = tb::core::triangulate(g, TriangulateOptions{1.5, true});
    const Mesh b = tb::core::triangulate(g, TriangulateOptions{1.5, true, 0.0});
    CHECK(a.points.size() == b.points.size());
    CHECK(a.triangles == b.triangles);
    // A bound longer than the grid's diagonal changes nothing either.
    const Mesh c = tb::core::triangulate(g, TriangulateOptions{1.5, true, 1000.0});
    CHECK(a.triangles == c.triangles);
}

TEST_CASE("a flat grid with max_edge becomes many triangles, each edge within the bound") {
    const HeightGrid g = terrain::named("flat", 129, 97, 0);
    CHECK(tb::core::triangulate(g, TriangulateOptions{1.0, true}).triangle_count() == 2);
    for (double max_edge : {1.5, 2.0, 2.3, 7.0, 16.0, 40.5}) {
        for (bool lock : {true, false}) {
            INFO("max_edge=", max_edge, " lock=", lock);
            const Mesh m = tb::core::triangulate(g, TriangulateOptions{1.0, lock, max_edge});
            CHECK(static_cast<double>(longest2(m)) <= max_edge * max_edge);
            // The area (128 x 96) over the largest triangle a bound L allows (L^2 sqrt(3)/4).
            const double least = 128.0 * 96.0 / (max_edge * max_edge * std::sqrt(3.0) / 4.0);
            CHECK(static_cast<double>(m.triangle_count()) >= least);
            check_all(g, 1.0, lock, max_edge);
        }
    }
}

TEST_CASE("edge bound, L-infinity bound and exact tiling hold over terrains, masks and borders") {
    const std::vector<std::string> kinds{"plane", "noise", "ridge", "saddle", "cliff", "spikes"};
    for (const auto& kind : kinds) {
        for (std::uint64_t seed : {3u, 11u}) {
            HeightGrid g = terrain::named(kind, 57 + static_cast<int>(seed), 41, seed);
            for (bool masked : {false, true}) {
                if (masked) {
                    terrain::Lcg r(seed * 7 + 1);
                    g.valid.assign(g.heights.size(), 1);
                    for (auto& v : g.valid) {
                        v = r.next() < 0.3 ? 0 : 1;
                    }
                } else {
                    g.valid.clear();
                }
                for (double eps : {0.5, 6.0}) {
                    for (double max_edge : {1.5, 3.2, 9.0}) {
                        for (bool lock : {true, false}) {
                            INFO(kind,
                                 " seed=",
                                 seed,
                                 " masked=",
                                 masked,
                                 " eps=",
                                 eps,
                                 " max_edge=",
                                 max_edge,
                                 " lock=",
                                 lock);
                            check_all(g, eps, lock, max_edge);
                        }
                    }
                }
            }
        }
    }
}

TEST_CASE("neighbouring windows share identical border vertices under max_edge") {
    const HeightGrid g = terrain::noise(129, 129, 21, 30.0, 1.0);
    const int size = 65;
    for (double eps : {0.5, 8.0}) {
        for (double max_edge : {5.0, 12.5}) {
            INFO("eps=", eps, " max_edge=", max_edge);
            const TriangulateOptions opt{eps, true, max_edge};
            const HeightGrid left = brute::window(g, 0, 0, size, size);
            const HeightGrid right = brute::window(g, size - 1, 0, size, size);
            const Mesh ml = tb::core::triangulate(left, opt);
            const Mesh mr = tb::core::triangulate(right, opt);
            const auto shared = brute::on_column(ml, size - 1);
            CHECK(shared == brute::on_column(mr, 0));
            CHECK(shared ==
                  tb::core::border_breakpoints(left, eps, 3, tb::core::max_step_for(max_edge)));
            for (std::size_t s = 1; s < shared.size(); ++s) {
                CHECK(shared[s] - shared[s - 1] <= static_cast<int>(max_edge));
            }
            CHECK(static_cast<double>(longest2(ml)) <= max_edge * max_edge);
            CHECK(static_cast<double>(longest2(mr)) <= max_edge * max_edge);
        }
    }
}

TEST_CASE("max_edge that is negative, not finite or shorter than 1.5 samples is rejected") {
    const HeightGrid g = terrain::named("flat", 9, 9, 0);
    for (double bad : {-1.0, 0.5, 1.0, 1.49, std::nan(""), HUGE_VAL}) {
        INFO("max_edge=", bad);
        CHECK_THROWS_AS(tb::core::triangulate(g, TriangulateOptions{1.0, true, bad}),
                        tb::InputError);
    }
    CHECK_NOTHROW(tb::core::triangulate(g, TriangulateOptions{1.0, true, 1.5}));
}
