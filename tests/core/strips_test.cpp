// triangulate_strips: strips meshed on their own threads and stitched keep every property of
// one mesh (L-infinity bound by the independent oracle, exact tiling, determinism), and every
// cut column carries exactly the optimal 1-D fit of its samples.
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <span>
#include <string>
#include <thread>
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

// The optimal 1-D fit of column x of g (what a locked border of either strip must hold).
std::vector<int> column_fit(const HeightGrid& g, int x, const TriangulateOptions& opt) {
    std::vector<float> z;
    std::vector<std::uint8_t> valid;
    for (int y = 0; y < g.height; ++y) {
        z.push_back(g.at(x, y));
        if (!g.valid.empty()) {
            valid.push_back(g.is_valid(x, y) ? 1 : 0);
        }
    }
    return tb::core::fit_breakpoints(z, valid, opt.eps, tb::core::max_step_for(opt.max_edge));
}

// Meshes g in `strips` strips and judges the result; returns it.
Mesh strips_and_judge(const HeightGrid& g, const TriangulateOptions& opt, int strips) {
    const Mesh m = tb::core::triangulate_strips(g, opt, strips);
    CHECK_NOTHROW(tb::core::check_mesh(m, g.width, g.height));
    const oracle::Verdict v = oracle::judge(m, g, opt.eps);
    CHECK_MESSAGE(v.problem.empty(), v.problem);
    CHECK_MESSAGE(v.over_eps == 0, "max error ", static_cast<double>(v.max_error));
    if (opt.max_edge > 0) {
        CHECK(tb::core::longest_edge(m) <= opt.max_edge);
    }
    const Mesh again = tb::core::triangulate_strips(g, opt, strips);
    CHECK(again.points == m.points);
    CHECK(again.z == m.z);
    CHECK(again.triangles == m.triangles);
    CHECK(again.halfedges == m.halfedges);
    // Every vertex appears once: the cut columns were not duplicated.
    std::vector<std::int64_t> keys;
    for (const auto& p : m.points) {
        keys.push_back(std::int64_t{p.y} * g.width + p.x);
    }
    std::sort(keys.begin(), keys.end());
    CHECK(std::adjacent_find(keys.begin(), keys.end()) == keys.end());
    return m;
}

} // namespace

TEST_CASE("strips stay within eps, tile the grid and repeat bit for bit (seed 5)") {
    const std::vector<std::pair<int, int>> sizes = {{65, 40}, {100, 65}, {129, 129}};
    for (const char* kind : {"saddle", "ridge", "cliff", "spikes", "noise"}) {
        for (const auto& [w, h] : sizes) {
            const HeightGrid g = terrain::named(kind, w, h, 5);
            for (double eps : {0.25, 2.0, 40.0}) {
                for (int strips : {2, 3}) {
                    INFO(kind, " ", w, "x", h, " eps=", eps, " strips=", strips);
                    const TriangulateOptions opt{.eps = eps, .lock_border = true};
                    const Mesh m = strips_and_judge(g, opt, strips);
                    // The cut columns hold exactly their own optimal 1-D fits.
                    const int n = std::min(strips, (w - 1) / (tb::core::kMinStripColumns - 1));
                    for (int k = 1; k < n; ++k) {
                        const int x = static_cast<int>(std::int64_t{w - 1} * k / n);
                        CHECK(brute::on_column(m, x) == column_fit(g, x, opt));
                    }
                }
            }
        }
    }
}

TEST_CASE("the strips' mesh is the same on one thread, two, or one per strip (seed 6)") {
    for (const char* kind : {"ridge", "spikes", "noise"}) {
        const HeightGrid g = terrain::named(kind, 129, 100, 6);
        const TriangulateOptions opt{.eps = 1.0, .lock_border = true};
        for (int strips : {2, 3}) {
            INFO(kind, " strips=", strips);
            const Mesh all = tb::core::triangulate_strips(g, opt, strips, 0);
            REQUIRE(!all.triangles.empty());
            for (int threads : {1, 2}) {
                const Mesh m = tb::core::triangulate_strips(g, opt, strips, threads);
                CHECK(m.points == all.points);
                CHECK(m.triangles == all.triangles);
            }
            // The other lanes handed to the caller's runner (here a thread per job, joined
            // after): the same mesh, and every job ran.
            std::vector<std::thread> jobs;
            const Mesh elsewhere =
                tb::core::triangulate_strips(g, opt, strips, 2, [&jobs](std::function<void()> job) {
                    jobs.emplace_back(std::move(job));
                });
            CHECK(jobs.size() == 1);
            for (std::thread& t : jobs) {
                t.join();
            }
            CHECK(elsewhere.points == all.points);
            CHECK(elsewhere.triangles == all.triangles);
        }
    }
}

TEST_CASE("strips honour max_edge and nodata, including a strip that is all nodata") {
    HeightGrid g = terrain::named("noise", 129, 97, 3);
    g.valid.assign(g.heights.size(), 1);
    for (int y = 0; y < g.height; ++y) {
        for (int x = 0; x < g.width; ++x) {
            // Columns 64.. are void (a whole strip of two), plus scattered holes elsewhere.
            const bool hole = x >= 64 || (x * 7 + y * 13) % 29 == 0;
            g.valid[static_cast<std::size_t>(y) * g.width + x] = hole ? 0 : 1;
        }
    }
    for (double max_edge : {0.0, 6.0}) {
        INFO("max_edge=", max_edge);
        strips_and_judge(g, {.eps = 1.0, .lock_border = true, .max_edge = max_edge}, 2);
    }
}

TEST_CASE("one strip, an unlocked border or a narrow grid mesh the grid whole") {
    const HeightGrid g = terrain::named("noise", 80, 50, 8);
    const TriangulateOptions locked{.eps = 1.5, .lock_border = true};
    const TriangulateOptions unlocked{.eps = 1.5, .lock_border = false};
    const auto same = [](const Mesh& a, const Mesh& b) {
        return a.points == b.points && a.triangles == b.triangles && a.halfedges == b.halfedges;
    };
    CHECK(same(tb::core::triangulate_strips(g, locked, 1), tb::core::triangulate(g, locked)));
    CHECK(same(tb::core::triangulate_strips(g, unlocked, 2), tb::core::triangulate(g, unlocked)));
    // 80 columns hold two strips of at least kMinStripColumns, not three.
    CHECK(same(tb::core::triangulate_strips(g, locked, 3),
               tb::core::triangulate_strips(g, locked, 2)));
    const HeightGrid narrow = terrain::named("noise", 40, 50, 8);
    CHECK(same(tb::core::triangulate_strips(narrow, locked, 2),
               tb::core::triangulate(narrow, locked)));
}

TEST_CASE("two strips of a 257 x 257 tile cost at most 2 % more triangles than one mesh, and "
          "two more per vertex of the cut") {
    // The locked cut column (128) holds its 1-D fit, which the whole mesh need not: about two
    // triangles per interior vertex of that fit, which is what dominates a coarse mesh of a
    // few hundred triangles.
    const HeightGrid g = terrain::noise(257, 257, 21, 300.0, 2.0);
    for (double eps : {1.0, 8.0}) {
        const TriangulateOptions opt{.eps = eps, .lock_border = true};
        const std::size_t whole = tb::core::triangulate(g, opt).triangle_count();
        const std::size_t split = strips_and_judge(g, opt, 2).triangle_count();
        const std::size_t cut = column_fit(g, 128, opt).size() - 2;
        INFO("eps=", eps, " whole ", whole, " strips ", split, " cut vertices ", cut);
        CHECK(split >= whole / 2);
        CHECK(static_cast<double>(split) <=
              1.02 * static_cast<double>(whole) + 2.0 * static_cast<double>(cut));
    }
}

TEST_CASE("strips refuse bad input as triangulate does, naming the sample in the whole grid") {
    HeightGrid g = terrain::named("ridge", 100, 40, 1);
    g.heights[static_cast<std::size_t>(7) * 100 + 90] = std::numeric_limits<float>::quiet_NaN();
    try {
        tb::core::triangulate_strips(g, {.eps = 1.0}, 2);
        FAIL("no error for a NaN height");
    } catch (const tb::InputError& e) {
        CHECK(std::string(e.what()).find("x=90 y=7") != std::string::npos);
    }
    const HeightGrid ok = terrain::named("ridge", 100, 40, 1);
    CHECK_THROWS_AS(tb::core::triangulate_strips(ok, {.eps = -1.0}, 2), tb::InputError);
}
