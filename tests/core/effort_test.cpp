// The effort levels (TriangulateOptions::effort): every level keeps the L-infinity bound on
// every valid sample (the independent oracle), the exact tiling, determinism and the locked
// borders; Best is today's split-merge bit for bit; the levels order their triangle counts.
#include <doctest/doctest.h>

#include <cstdint>
#include <cstring>
#include <string>
#include <utility>
#include <vector>

#include "core/breakpoints.hpp"
#include "core/error.hpp"
#include "core/triangulate.hpp"
#include "tests/core/brute_force.hpp"
#include "tests/core/linf_oracle.hpp"
#include "tests/core/terrains.hpp"

namespace {

using tb::core::Effort;
using tb::core::HeightGrid;
using tb::core::Mesh;
using tb::core::TriangulateOptions;

const Effort kLevels[] = {Effort::Fast, Effort::Balanced, Effort::Best};

// Meshes g at one level, judges it by the oracle and check_mesh, checks determinism.
Mesh mesh_and_judge(const HeightGrid& g, TriangulateOptions opt) {
    const Mesh m = tb::core::triangulate(g, opt);
    CHECK_NOTHROW(tb::core::check_mesh(m, g.width, g.height));
    const oracle::Verdict v = oracle::judge(m, g, opt.eps);
    CHECK_MESSAGE(v.problem.empty(), v.problem);
    CHECK_MESSAGE(v.over_eps == 0, "max error ", static_cast<double>(v.max_error));
    if (opt.max_edge > 0.0) {
        CHECK(tb::core::longest_edge(m) <= opt.max_edge);
    }
    const Mesh again = tb::core::triangulate(g, opt);
    CHECK(again.points == m.points);
    CHECK(again.z == m.z);
    CHECK(again.triangles == m.triangles);
    CHECK(again.halfedges == m.halfedges);
    return m;
}

// FNV-1a over every vertex (x, y, z's bits) and every half-edge (start, twin), 32-bit words.
std::uint64_t mesh_hash(const Mesh& m) {
    std::uint64_t h = 14695981039346656037ULL;
    const auto mix = [&h](std::uint32_t word) { h = (h ^ word) * 1099511628211ULL; };
    for (std::size_t v = 0; v < m.points.size(); ++v) {
        std::uint32_t bits = 0;
        std::memcpy(&bits, &m.z[v], sizeof bits);
        mix(static_cast<std::uint32_t>(m.points[v].x));
        mix(static_cast<std::uint32_t>(m.points[v].y));
        mix(bits);
    }
    for (std::size_t e = 0; e < m.triangles.size(); ++e) {
        mix(m.triangles[e]);
        mix(m.halfedges[e]);
    }
    return h;
}

const std::vector<std::string> kKinds = {
    "flat", "plane", "saddle", "ridge", "cliff", "spikes", "noise"};

} // namespace

TEST_CASE("parse_effort reads the three names and to_string gives them back") {
    for (const Effort e : kLevels) {
        CHECK(tb::core::parse_effort(tb::core::to_string(e)) == e);
    }
    CHECK(std::string(tb::core::to_string(Effort::Fast)) == "fast");
    CHECK(std::string(tb::core::to_string(Effort::Balanced)) == "balanced");
    CHECK(std::string(tb::core::to_string(Effort::Best)) == "best");
}

TEST_CASE("parse_effort refuses anything else with an InputError naming the choices") {
    for (const char* bad : {"", "Fast", "BEST", "medium", " fast", "fast ", "balanced\n", "0"}) {
        INFO("name=\"", bad, "\"");
        CHECK_THROWS_AS(tb::core::parse_effort(bad), tb::InputError);
        try {
            tb::core::parse_effort(bad);
        } catch (const tb::InputError& e) {
            CHECK(std::string(e.what()).find("expected fast, balanced or best") !=
                  std::string::npos);
        }
    }
    // A value outside the enumeration (a caller's cast) is refused before any work.
    const HeightGrid g = terrain::named("plane", 9, 9, 0);
    TriangulateOptions opt{.eps = 1.0};
    opt.effort = static_cast<Effort>(7);
    CHECK_THROWS_AS(tb::core::check_input(g, opt), tb::InputError);
    CHECK_THROWS_AS(tb::core::triangulate(g, opt), tb::InputError);
}

TEST_CASE("Best is the default and gives the meshes of 9ec9617 bit for bit (seeds 3, 4, 21)") {
    // Hashes of the meshes the mesher gave before the effort setting existed (commit 9ec9617),
    // from the default options: the tiler, which sets no level yet, keeps its tiles' bytes.
    struct Case {
        const char* name;
        HeightGrid grid;
        TriangulateOptions options;
        std::size_t triangles;
        std::uint64_t hash;
    };
    const Case cases[] = {
        {"noise 257x257 seed 3 eps 2",
         terrain::noise(257, 257, 3, 200.0, 3.0),
         {.eps = 2.0},
         8249,
         0xbf0ee8c469ee48dfULL},
        {"saddle 257x257 eps 0.5",
         terrain::named("saddle", 257, 257, 0),
         {.eps = 0.5},
         450,
         0x9f5dc6a45f2dbb48ULL},
        {"noise 300x101 seed 4 eps 0.5 free borders",
         terrain::noise(300, 101, 4, 50.0, 1.0),
         {.eps = 0.5, .lock_border = false},
         9644,
         0xfae37a730fbda412ULL},
        {"noise 129x129 seed 21 eps 4 max_edge 12",
         terrain::noise(129, 129, 21, 120.0, 3.0),
         {.eps = 4.0, .max_edge = 12.0},
         628,
         0xf9f3897550d4d5fbULL},
    };
    CHECK(TriangulateOptions{}.effort == Effort::Best);
    for (const Case& c : cases) {
        INFO(c.name);
        const Mesh m = tb::core::triangulate(c.grid, c.options);
        CHECK(m.triangle_count() == c.triangles);
        CHECK(mesh_hash(m) == c.hash);
        TriangulateOptions best = c.options;
        best.effort = Effort::Best;
        CHECK(mesh_hash(tb::core::triangulate(c.grid, best)) == c.hash);
    }
}

TEST_CASE("every level keeps every sample within eps at small sizes, eps tiny to huge (seed 7)") {
    const std::vector<std::pair<int, int>> sizes = {
        {2, 2}, {2, 9}, {9, 2}, {3, 3}, {17, 17}, {33, 20}, {20, 41}};
    for (const Effort effort : kLevels) {
        for (const auto& kind : kKinds) {
            for (const auto& [w, h] : sizes) {
                const HeightGrid g = terrain::named(kind, w, h, 7);
                for (double eps : {0.0009765625, 0.25, 1.5, 10.0, 1000.0}) {
                    INFO(tb::core::to_string(effort), " ", kind, " ", w, "x", h, " eps=", eps);
                    mesh_and_judge(g, {.eps = eps, .effort = effort});
                }
            }
        }
    }
}

TEST_CASE("every level stays within eps on 65x65, free borders and max_edge too (seed 11)") {
    for (const Effort effort : kLevels) {
        for (const auto& kind : kKinds) {
            const HeightGrid g = terrain::named(kind, 65, 65, 11);
            for (double eps : {0.125, 2.0, 16.0}) {
                for (bool lock : {true, false}) {
                    for (double max_edge : {0.0, 6.0}) {
                        INFO(tb::core::to_string(effort),
                             " ",
                             kind,
                             " eps=",
                             eps,
                             " lock_border=",
                             lock,
                             " max_edge=",
                             max_edge);
                        mesh_and_judge(g,
                                       {.eps = eps,
                                        .lock_border = lock,
                                        .max_edge = max_edge,
                                        .effort = effort});
                    }
                }
            }
        }
    }
}

TEST_CASE(
    "every level stays within eps on 257x257 noise, 300x101 and nodata holes (seeds 3, 4, 9)") {
    HeightGrid holes = terrain::noise(80, 60, 9, 40.0, 2.0);
    holes.valid.assign(holes.heights.size(), 1);
    for (int y = 10; y < 30; ++y) {
        for (int x = 20; x < 50; ++x) {
            const std::size_t i = static_cast<std::size_t>(y) * 80 + x;
            holes.valid[i] = 0;
            holes.heights[i] = 4000.0f; // a filled void far from the terrain
        }
    }
    for (int x = 0; x < 80; ++x) {
        holes.valid[static_cast<std::size_t>(x)] = x % 3 == 0 ? 0 : 1;
    }
    for (const Effort effort : kLevels) {
        INFO(tb::core::to_string(effort));
        mesh_and_judge(terrain::noise(257, 257, 3, 200.0, 3.0), {.eps = 2.0, .effort = effort});
        mesh_and_judge(terrain::noise(257, 257, 3, 200.0, 3.0), {.eps = 40.0, .effort = effort});
        mesh_and_judge(terrain::noise(300, 101, 4, 50.0, 1.0),
                       {.eps = 0.5, .lock_border = false, .effort = effort});
        for (bool lock : {true, false}) {
            mesh_and_judge(holes, {.eps = 1.0, .lock_border = lock, .effort = effort});
        }
    }
}

TEST_CASE("the border vertices are the same at every level: the borders' 1-D fits (seed 21)") {
    // So a level never changes what a tile shares with its neighbours: windows that share a
    // column or row get identical vertices there whatever level each was made with.
    const HeightGrid g = terrain::noise(129, 129, 21, 120.0, 3.0);
    for (double eps : {0.5, 4.0, 40.0}) {
        for (double max_edge : {0.0, 10.0}) {
            INFO("eps=", eps, " max_edge=", max_edge);
            const int step = tb::core::max_step_for(max_edge);
            const HeightGrid left = brute::window(g, 0, 0, 65, 65);
            const HeightGrid right = brute::window(g, 64, 0, 65, 65);
            const HeightGrid below = brute::window(g, 0, 64, 65, 65);
            const auto col = tb::core::border_breakpoints(left, eps, 3, step);
            const auto row = tb::core::border_breakpoints(left, eps, 1, step);
            for (const Effort effort : kLevels) {
                INFO(tb::core::to_string(effort));
                const TriangulateOptions opt{.eps = eps, .max_edge = max_edge, .effort = effort};
                const Mesh ml = mesh_and_judge(left, opt);
                CHECK(brute::on_column(ml, 64) == col);
                CHECK(brute::on_row(ml, 64) == row);
                CHECK(brute::on_column(ml, 0) == tb::core::border_breakpoints(left, eps, 2, step));
                CHECK(brute::on_row(ml, 0) == tb::core::border_breakpoints(left, eps, 0, step));
                CHECK(brute::on_column(mesh_and_judge(right, opt), 0) == col);
                CHECK(brute::on_row(mesh_and_judge(below, opt), 0) == row);
            }
        }
    }
}

TEST_CASE(
    "the levels order their triangles on rough terrain: Fast > Balanced > Best (seeds 3, 31-34)") {
    // Not a theorem (a pass limited to small holes removes other vertices first, and so
    // changes which can go later), but on rough terrain every level that works harder must end
    // with fewer triangles, or it is not worth its time.
    std::vector<std::pair<HeightGrid, double>> rough = {
        {terrain::noise(257, 257, 3, 200.0, 3.0), 2.0},
        {terrain::noise(257, 257, 3, 200.0, 3.0), 20.0}};
    for (std::uint64_t seed = 31; seed <= 34; ++seed) {
        rough.push_back({terrain::noise(129, 97, seed, 80.0, 6.0), 1.0});
    }
    for (const auto& [g, eps] : rough) {
        INFO(g.width, "x", g.height, " eps=", eps);
        const std::size_t fast =
            tb::core::triangulate(g, {.eps = eps, .effort = Effort::Fast}).triangle_count();
        const std::size_t balanced =
            tb::core::triangulate(g, {.eps = eps, .effort = Effort::Balanced}).triangle_count();
        const std::size_t best =
            tb::core::triangulate(g, {.eps = eps, .effort = Effort::Best}).triangle_count();
        MESSAGE(g.width,
                "x",
                g.height,
                " eps ",
                eps,
                ": fast ",
                fast,
                ", balanced ",
                balanced,
                ", best ",
                best);
        CHECK(best < balanced);
        CHECK(balanced < fast);
    }
}

TEST_CASE("Fast and Balanced run one merge pass; Best up to four (seeds 3, 21)") {
    const HeightGrid g = terrain::noise(257, 257, 3, 200.0, 3.0);
    for (const Effort effort : kLevels) {
        INFO(tb::core::to_string(effort));
        tb::core::TriangulatePhases phases;
        const Mesh m = tb::core::triangulate(g, {.eps = 2.0, .effort = effort}, &phases);
        CHECK(phases.removed > 0);
        CHECK(m.triangle_count() < phases.split_triangles);
        if (effort == Effort::Best) {
            CHECK(phases.merge_passes >= 2);
            CHECK(phases.merge_passes <= 4);
        } else {
            CHECK(phases.merge_passes == 1);
        }
    }
}

TEST_CASE("triangulate_strips keeps the bound and the cut columns' fits at every level (seed 5)") {
    const HeightGrid g = terrain::noise(161, 90, 5, 90.0, 2.0);
    for (const Effort effort : kLevels) {
        for (double eps : {0.5, 8.0}) {
            INFO(tb::core::to_string(effort), " eps=", eps);
            const TriangulateOptions opt{.eps = eps, .effort = effort};
            const Mesh m = tb::core::triangulate_strips(g, opt, 3, 2);
            CHECK_NOTHROW(tb::core::check_mesh(m, g.width, g.height));
            const oracle::Verdict v = oracle::judge(m, g, eps);
            CHECK_MESSAGE(v.problem.empty(), v.problem);
            CHECK_MESSAGE(v.over_eps == 0, "max error ", static_cast<double>(v.max_error));
            const Mesh again = tb::core::triangulate_strips(g, opt, 3, 1);
            CHECK(again.points == m.points);
            CHECK(again.triangles == m.triangles);
            CHECK(again.halfedges == m.halfedges);
        }
    }
}

TEST_CASE("a grid of 2^18 samples splits its work in two: the same mesh on 1 or 2 threads") {
    // 521 x 521 > 2^18 samples: the scan lines' fits, the first scan and the error check run in
    // halves, and every merge pass works the halves left and right of column 260 apart, then the
    // vertices whose neighbourhood crosses it. Bound, tiling, determinism, and the same mesh bit
    // for bit whether the halves run on one thread or two.
    const HeightGrid g = terrain::noise(521, 521, 41, 200.0, 3.0);
    REQUIRE(static_cast<std::size_t>(g.width) * g.height >= std::size_t{1} << 18);
    for (const Effort effort : kLevels) {
        for (bool lock : {true, false}) {
            const double eps = lock ? 2.0 : 12.0;
            const double max_edge = lock ? 0.0 : 24.0;
            INFO(tb::core::to_string(effort), " lock_border=", lock, " eps=", eps);
            TriangulateOptions opt{
                .eps = eps, .lock_border = lock, .max_edge = max_edge, .effort = effort};
            CHECK(opt.threads == 2);
            const Mesh two = mesh_and_judge(g, opt);
            opt.threads = 1;
            const Mesh one = tb::core::triangulate(g, opt);
            CHECK(one.points == two.points);
            CHECK(one.z == two.z);
            CHECK(one.triangles == two.triangles);
            CHECK(one.halfedges == two.halfedges);
            CHECK(tb::core::max_error(two, g, 2) == tb::core::max_error(two, g, 1));
        }
    }
    CHECK(tb::core::anchor_points(g, 2.0, 0, true, 2) ==
          tb::core::anchor_points(g, 2.0, 0, true, 1));
    TriangulateOptions bad{.eps = 2.0};
    for (int threads : {0, 3, -1}) {
        bad.threads = threads;
        CHECK_THROWS_AS(tb::core::check_input(g, bad), tb::InputError);
    }
}
